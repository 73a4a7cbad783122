"""The ``o3d-lsmesh`` command line: subcommands generated from :data:`~o3d_lsmesh.app.ops.OPS`.

Every operation's flags come from its option table (``ops.py``); the commands with a flow of their
own are in :mod:`o3d_lsmesh.app.commands`. Exit codes: 0 success; 2 a user error, one line on
stderr naming the flag or the file (an :class:`~o3d_lsmesh.core.errors.InputError` is mapped to
its flag by ``param``); 1 a picture that could not be drawn, or any other error with its traceback
(a bug); 130 an interrupt. Docs: ``docs/cli.rst`` (generated from ``--help``).
"""

from __future__ import annotations

import argparse
import dataclasses
import inspect
import json
import re
import sys
import textwrap
import time
import traceback
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..core.errors import InputError
from .files import WRITABLE, CLIError, check_output, read_input, write_output
from .ops import OPS, Option, TaskContext
from .tasks import jsonable

__all__ = ["CLIError", "PictureError", "Run", "build_parser", "main"]

PROG = "o3d-lsmesh"


class PictureError(Exception):
    """A picture that could not be drawn (no working renderer): one line on stderr, exit code 1."""


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter, argparse.RawDescriptionHelpFormatter):
    """``--help`` shows every option's default and keeps the examples' line breaks."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        # a required option has no default; one resolved later (None: the API's choice) says so itself
        if action.required or (action.help and "(default:" in action.help):
            return action.help
        return super()._get_help_string(action)


class Parser(argparse.ArgumentParser):
    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", HelpFormatter)  # subparsers are made with this class too
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> Any:  # one line, no usage block
        raise CLIError(f"{self.prog}: error: {message} (see {self.prog} --help)")


def argparse_type(parse: Callable[[Any], Any]) -> Callable[[str], Any]:
    """``parse`` as an argparse type (its ``ValueError`` the flag's one-line error)."""

    def convert(text: str) -> Any:
        try:
            return parse(text)
        except ValueError as error:
            raise argparse.ArgumentTypeError(str(error)) from None

    return convert


def add_option(parser: Any, option: Option, **overrides: Any) -> None:
    """The flag of ``option`` (a switch, a choice, or a value its parser checks)."""
    kwargs: dict[str, Any] = {"help": option.help.replace("%", "%%"), "default": option.default}
    if option.is_flag:
        kwargs["action"] = "store_true"
    elif getattr(option.parse, "choices", None):
        choices = option.parse.choices  # type: ignore[attr-defined]
        kwargs.update(choices=choices, type=type(choices[0]))
    else:
        kwargs["type"] = argparse_type(option.parse)
    if option.required:
        kwargs.update(required=True, default=None)
    parser.add_argument(option.cli_flag, dest=option.name, **{**kwargs, **overrides})


def add_command(
    sub: Any, common: argparse.ArgumentParser, handler: Callable[..., int], arguments: dict[str, str]
) -> argparse.ArgumentParser:
    """Add the subcommand ``handler.__name__`` with its positional ``arguments`` (name: help) and,
    when it names an operation of :data:`OPS`, that operation's flags.

    ``--help`` is the handler's docstring: its first line the summary, its last paragraph
    (``example: ...``) the example, the paragraphs between the description.
    """
    name = handler.__name__
    summary, *body, example = inspect.cleandoc(handler.__doc__ or "").split("\n\n")
    parser = sub.add_parser(
        name,
        parents=[common],
        help=summary.rstrip("."),
        description="\n\n".join(textwrap.fill(" ".join(p.split()), 79) for p in body),
        epilog=f"example:\n  {PROG} {name} {example.removeprefix('example: ')}",
    )
    for argument, text in arguments.items():
        parser.add_argument(argument, metavar=argument.upper(), help=text)
    options = [option for option in OPS[name].options if option.cli] if name in OPS else []
    for option in options:
        add_option(parser, option)
    flags = {option.api_param: option.cli_flag for option in options}
    parser.set_defaults(handler=handler, positionals=tuple(arguments), flags=flags)
    return parser


# --------------------------------------------------------------------------- output


class Run:
    """Output policy of one invocation: progress bars, human report, JSON."""

    def __init__(self, args: argparse.Namespace):
        self.args = args
        self.quiet, self.json = args.quiet, args.json
        self.progress = not self.quiet
        # with --json, stdout carries only the JSON object: the report goes to stderr
        self.stream = sys.stderr if self.json else sys.stdout

    def say(self, text: str) -> None:
        if not self.quiet:
            print(text, file=self.stream, flush=True)

    def finish(self, mesh: Any = None, **fields: Any) -> int:
        """With ``--json``, print the report: the command, its files, the mesh's size, then ``fields``."""
        if self.json:
            report = {
                "command": self.args.command,
                **{n: getattr(self.args, n) for n in self.args.positionals},
            }
            if mesh is not None:
                report.update(vertices=len(mesh.vertices), triangles=len(mesh.triangles))
            print(json.dumps(jsonable({**report, **fields}), indent=2), flush=True)
        return 0


# --------------------------------------------------------------------------- errors


def _spell(param: str, args: argparse.Namespace | None) -> str:
    """The words of the command line for the Python parameter ``param``: its flag or the file named."""
    flags = getattr(args, "flags", {})
    positionals = getattr(args, "positionals", ())
    if param in flags:
        return flags[param]
    name = "input" if param == "mesh" and "input" in positionals else param
    if name in positionals:
        return f"{name.upper()} {getattr(args, name)!r}"
    return "--" + param.replace("_", "-") if hasattr(args, param) else param


def user_message(error: InputError, args: argparse.Namespace | None) -> str:
    """``error`` in the words of the command line: its ``param`` spelled as the command's flag or file.

    The flag replaces the parameter leading the message (``"<param> must ..."``), or prefixes it; a
    parameter with an underscore (no English word has one) is its flag wherever the message names it,
    unless a switch's (it may mean the negation). An option quoted with one of its choices
    (``method='local'``) reads ``--method local``.
    """
    text, param = str(error), error.param
    for name, flag in getattr(args, "flags", {}).items():
        option = _option(args, name)
        for value in getattr(getattr(option, "parse", None), "choices", None) or ():
            text = text.replace(f"{name}={value!r}", f"{flag} {value}")
    if param:
        word = _spell(param, args)
        option = _option(args, param)
        if "_" in param and param in getattr(args, "flags", {}) and not (option and option.is_flag):
            text = re.sub(rf"\b{re.escape(param)}\b", word, text)
        elif text.startswith(param + " "):
            text = word + text[len(param) :]
        if word != param and word not in text:
            text = f"{word}: {text}"
    return text


def _option(args: argparse.Namespace | None, param: str) -> Option | None:
    op = OPS.get(getattr(args, "command", None) or "")
    return next((o for o in op.options if o.api_param == param), None) if op else None


def fail(text: str, code: int) -> int:
    from ..core.progress import close_all

    close_all()
    sys.stdout.flush()
    print(text if text.startswith(PROG) else f"{PROG}: error: {text}", file=sys.stderr, flush=True)
    return code


def internal_error(error: BaseException) -> int:
    from ..core.progress import close_all

    close_all()
    traceback.print_exception(type(error), error, error.__traceback__, file=sys.stderr)
    return fail(f"{PROG}: internal error (a bug in o3d-lsmesh, not in your input: please report it)", 1)


def _show_warning(message: Warning | str, category: type[Warning], *_args: Any, **_kwargs: Any) -> None:
    from ..core.progress import Progress

    Progress.write(f"{PROG}: warning: {message}")


# --------------------------------------------------------------------------- the operations' commands


def shape_change_text(change: dict) -> str:
    """One line for :func:`~o3d_lsmesh.metrics.shape_change`: a closed mesh's volume change, an open one's
    inward shift along the normals (its volume about the origin means nothing)."""
    if change["closed"]:
        percent = change["volume_change_percent"]
        return "volume change " + ("n/a (input volume 0)" if percent is None else f"{percent:+.3f}%")
    if change["inward_shift_mean"] is None:
        return "open surface (no volume; no vertex correspondence for a shift)"
    rim, interior = (change[f"inward_shift_{key}"] for key in ("rim", "interior"))
    return (
        f"open surface (no volume): inward shift along the normals {change['inward_shift_mean']:.4g} "
        f"(rim {'n/a' if rim is None else f'{rim:.4g}'}, "
        f"interior {'n/a' if interior is None else f'{interior:.4g}'})"
    )


def draw(
    meshes: list[Any], path: str, run: Run, *, what: str = "left: input, right: result", **options: Any
) -> str:
    """Draw ``meshes`` side by side into ``path``; :class:`PictureError` when no renderer works."""
    from .render import render

    start = time.perf_counter()
    try:
        render(meshes, path, **options)
    except RuntimeError as error:  # Filament and the raycasting fallback both failed: not the input's fault
        raise PictureError(str(error)) from error
    run.say(f"picture ({time.perf_counter() - start:.1f} s): {path}  ({what})")
    return path


def run_op(name: str, mesh: Any, args: argparse.Namespace, run: Run) -> tuple[Any, dict, float]:
    """Run the operation ``name`` on ``mesh`` with the command line's options; the result, metrics, seconds."""
    context = TaskContext(args.input, args.input, None, progress=run.progress)
    options = {option.name: getattr(args, option.name, option.default) for option in OPS[name].options}
    start = time.perf_counter()
    out, metrics = OPS[name].function(mesh, options, context)
    return out, metrics, time.perf_counter() - start


def run_file_op(name: str, args: argparse.Namespace, run: Run, *extra: Any) -> tuple[Any, Any, dict, float]:
    """The flow of an op's subcommand: check OUTPUT and the ``extra`` ``(path, suffixes)`` outputs, read
    INPUT, run the op, write its mesh or bytes; the input, the output, the metrics and the seconds."""
    kind = OPS[name].output
    check_output(args.output, [args.input], force=args.force, suffixes=None if kind == "bytes" else WRITABLE)
    for path, suffixes in extra:
        if path:
            check_output(path, [args.input], force=args.force, suffixes=suffixes)
    mesh = read_input(args.input)
    out, metrics, seconds = run_op(name, mesh, args, run)
    Path(args.output).write_bytes(out) if kind == "bytes" else write_output(args.output, out)
    return mesh, out, metrics, seconds


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
    if args.level and given:  # multiresolution fairing fairs every level with its own defaults
        raise CLIError(
            f"{', '.join(given)} cannot be combined with --level (multiresolution fairing does not take "
            f"{'them' if len(given) > 1 else 'it'}), got --level {args.level}"
        )
    from ..fairing.constrained import resolved_options

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
    from .._o3d import read_mesh
    from ..holes import find_holes

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


# --------------------------------------------------------------------------- the parser and main


def build_parser() -> argparse.ArgumentParser:
    from . import commands

    parser = Parser(
        prog=PROG,
        description=textwrap.fill(
            "Least-squares meshes and constrained fairing for Open3D meshes. Reads and writes every "
            "triangle-mesh format Open3D does (PLY, OBJ, STL, OFF, glTF). Each call imports Open3D "
            f"(about 2 s): for many files use '{PROG} batch', which pays that once per worker.",
            79,
        ),
        epilog=f"example:\n  {PROG} denoise scan.ply smooth.ply\n  {PROG} denoise --help",
    )
    from importlib.metadata import PackageNotFoundError, version

    try:
        parser.add_argument("--version", action="version", version=f"{PROG} {version('o3d_lsmesh')}")
    except PackageNotFoundError:  # pragma: no cover - a source tree that was never installed
        pass
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--quiet", action="store_true", help="no progress bars and no report")
    common.add_argument("--json", action="store_true", help="print the metrics as one JSON object on stdout")
    writing = argparse.ArgumentParser(add_help=False, parents=[common])
    writing.add_argument("--force", action="store_true", help="allow overwriting an input file")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser, required=True)
    commands.add_parsers(sub, writing, common)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``o3d-lsmesh`` with ``argv`` (default ``sys.argv[1:]``); return the exit code.

    Exit codes: 0 success, 2 a user error (one line on stderr), 1 a picture that could not be
    drawn or an internal error (with its traceback), 130 an interrupt.
    """
    args = None
    try:
        with warnings.catch_warnings():
            # a warning is one line naming the program, printed above the bar, not a source line
            warnings.showwarning = _show_warning
            args = build_parser().parse_args(argv)
            return int(args.handler(args, Run(args)))
    except CLIError as error:
        return fail(str(error), 2)
    except InputError as error:  # by class: any other ValueError or TypeError is a bug (below)
        return fail(user_message(error, args), 2)
    except MemoryError:
        return fail("not enough memory for this request: try a smaller mesh or smaller options", 2)
    except OSError as error:
        return fail(f"{error.strerror or error}: {error.filename or ''}".rstrip(": "), 2)
    except PictureError as error:
        return fail(str(error), 1)
    except KeyboardInterrupt:
        return fail(f"{PROG}: interrupted", 130)
    except Exception as error:
        return internal_error(error)
