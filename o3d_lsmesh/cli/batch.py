"""``o3d-lsmesh batch``: one operation or a pipeline over many files (:mod:`o3d_lsmesh.batch`)."""

from __future__ import annotations

import argparse
import os
import textwrap
import time
from collections import Counter
from typing import Any

from .._batch_ops import OPS, Option
from ._common import CLIError, Run, add_command


def add_parsers(sub: Any, common: argparse.ArgumentParser) -> None:
    p = add_command(sub, common, batch, {})
    p.add_argument(
        "inputs", nargs="+", metavar="INPUT", help="files, folders (searched recursively) or globs"
    )
    p.add_argument("outdir", metavar="OUTDIR", help="folder for the outputs and the report")
    p.set_defaults(positionals=("inputs", "outdir"))
    operations = ", ".join(f"{name} ({op.help})" for name, op in OPS.items())
    p.description = f"{p.description}\n\n" + textwrap.fill(f"Operations: {operations}.", 79)
    p.add_argument(
        "--op", required=True, help="an operation or a pipeline in order, e.g. denoise or denoise,compare"
    )
    p.add_argument("--set", action="append", default=[], metavar="OP.NAME=VALUE", help="an option of one op")
    p.add_argument("--workers", type=int, help="local worker processes (default: CPUs; 0: this process)")
    p.add_argument("--threads-per-worker", type=int, default=1, help="threads of each worker")
    where = p.add_mutually_exclusive_group()
    where.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="existing Dask scheduler, e.g. tcp://host:8786 (default: $DASK_SCHEDULER_ADDRESS)",
    )
    where.add_argument(
        "--scheduler-file", metavar="FILE", help="existing scheduler's JSON file (default: none)"
    )
    p.add_argument(
        "--resume", action="store_true", help="skip inputs the report lists as ok with the same key"
    )
    p.add_argument(
        "--report",
        metavar="FILE",
        help="JSON-lines report, one record per file (default: OUTDIR/batch_report.jsonl)",
    )
    p.add_argument("--retries", type=int, default=1, help="runs of a task whose worker died before it fails")
    p.add_argument("--fail-fast", action="store_true", help="stop at the first failure")
    p.add_argument(
        "--task-timeout",
        type=float,
        default=3600.0,
        metavar="SECONDS",
        help="a file still running after this long fails (TaskTimeout; 0: no limit; default: 3600)",
    )
    p.add_argument("--suffix", default=".ply", help="output mesh format (.ply .obj .stl .off .gltf)")
    _option_flags(p)


def _option_flags(parser: argparse.ArgumentParser) -> None:
    """One flag per option name of the registered ops; values are parsed per op by resolve_options."""
    group = parser.add_argument_group(
        "operation options (each applies to every op of the pipeline that has it; "
        "--set OP.NAME=VALUE for one op)"
    )
    seen: dict[str, list[tuple[str, Option]]] = {}
    for op in OPS.values():
        for option in op.options:
            seen.setdefault(option.name, []).append((op.name, option))
    for name, owners in seen.items():
        option = owners[0][1]
        helps = {o.help for _, o in owners}
        text = (
            f"{option.help} [{', '.join(n for n, _ in owners)}]"
            if len(helps) == 1
            else "; ".join(f"{n}: {o.help}" for n, o in owners)
        )
        text = text.replace("%", "%%")  # argparse %-formats help
        # SUPPRESS: an option not given is left to each op's default (and --help shows none)
        kwargs: dict[str, Any] = {"action": "store_true"} if option.is_flag else {"metavar": "VALUE"}
        group.add_argument(
            option.cli_flag, dest=f"opt_{name}", default=argparse.SUPPRESS, help=text, **kwargs
        )


def batch(args: argparse.Namespace, run: Run) -> int:
    """Run an operation over many files (Dask cluster or local).

    Run an operation, or a pipeline of them, over many mesh files, each as one task on a local Dask
    cluster (default), an existing one (--scheduler), or in this process without Dask: Open3D is
    imported once per worker, not once per file. Exit code 0 when every file succeeded, 2 when
    any failed (the report lists why).

    example: scans/ out/ --op fill,denoise --workers 2
    """
    from ..batch import run as run_batch
    from ..batch import summarize

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
            workers=args.workers,
            threads_per_worker=args.threads_per_worker,
            scheduler=args.scheduler,
            scheduler_file=args.scheduler_file,
            resume=args.resume,
            report=report,
            retries=args.retries,
            fail_fast=args.fail_fast,
            suffix=args.suffix,
            force=args.force,
            progress=run.progress,
            task_timeout=args.task_timeout,
        )
    except ImportError as error:  # --scheduler without dask installed
        raise CLIError(str(error)) from None
    seconds = time.perf_counter() - start
    counts = Counter(record["status"] for record in records)
    run.say(summarize(records, seconds))
    run.say(f"report: {report}")
    run.finish(
        op=args.op,
        report=report,
        seconds=seconds,
        counts=dict(counts),
        failed=[r["input"] for r in records if r["status"] == "failed"],
    )
    return 0 if counts["failed"] == 0 and counts["cancelled"] == 0 else 2
