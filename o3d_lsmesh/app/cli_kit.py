"""The command-line kit every ``o3d-lsmesh`` subcommand uses: the parser and its help format, the
flags of an operation's option table (:data:`~o3d_lsmesh.app.ops.OPS`), the output policy of one
invocation (:class:`Run`), pictures, and the flow that runs an operation on a file.
"""

from __future__ import annotations

import argparse
import inspect
import json
import sys
import textwrap
import time
from pathlib import Path
from typing import Any, Callable

from . import render as rendering
from .files import WRITABLE, CLIError, check_output, read_input, write_output
from .ops import OPS, Option, TaskContext
from .tasks import jsonable

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


def add_option(parser: Any, option: Option) -> None:
    """The flag of ``option`` (a switch, a choice, or a value its parser checks)."""
    kwargs: dict[str, Any] = {"help": option.help.replace("%", "%%"), "default": option.default}
    if option.metavar:
        kwargs["metavar"] = option.metavar
    if option.is_flag:
        kwargs["action"] = "store_true"
    elif getattr(option.parse, "choices", None):
        choices = option.parse.choices  # type: ignore[attr-defined]
        kwargs.update(choices=choices, type=type(choices[0]))
    else:  # (int, float, str as themselves: argparse's own message for them)
        kwargs["type"] = option.parse if isinstance(option.parse, type) else argparse_type(option.parse)
    if option.required:
        kwargs.update(required=True, default=None)
    parser.add_argument(option.cli_flag, dest=option.name, **kwargs)


def add_command(
    sub: Any, common: argparse.ArgumentParser, handler: Callable[..., int], arguments: dict, *extra: Option
) -> argparse.ArgumentParser:
    """Add the subcommand ``handler.__name__`` with its positional ``arguments`` (name: help), the
    flags of the operation of :data:`OPS` it names if any, then the flags of its ``extra`` options.

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
    options += extra
    for option in options:
        add_option(parser, option)
    flags = {option.api_param: option.cli_flag for option in options}
    parser.set_defaults(handler=handler, positionals=tuple(arguments), flags=flags)
    return parser


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
    start = time.perf_counter()
    try:
        rendering.render(meshes, path, **options)
    except RuntimeError as error:  # Filament and the raycasting fallback both failed: not the input's fault
        raise PictureError(str(error)) from error
    run.say(f"picture ({time.perf_counter() - start:.1f} s): {path}  ({what})")
    return path


def run_op(name: str, mesh: Any, args: argparse.Namespace, run: Run) -> tuple[Any, dict, float]:
    """Run the operation ``name`` on ``mesh`` with the command line's options; the result, metrics, seconds."""
    context = TaskContext(args.input, args.input, None, progress=run.progress)
    start = time.perf_counter()
    out, metrics = OPS[name].function(mesh, op_options(name, args), context)
    return out, metrics, time.perf_counter() - start


def op_options(name: str, args: argparse.Namespace) -> dict:
    """The options of the operation ``name`` from the command line, checked as batch checks them."""
    op = OPS[name]
    options = {option.name: getattr(args, option.name, option.default) for option in op.options}
    if op.check is not None:
        op.check(options)
    return options


def run_file_op(name: str, args: argparse.Namespace, run: Run, *extra: Any) -> tuple[Any, Any, dict, float]:
    """The flow of an op's subcommand: check OUTPUT and the ``extra`` ``(path, suffixes, flag)`` outputs, read
    INPUT, run the op, write its mesh or bytes; the input, the output, the metrics and the seconds."""
    kind = OPS[name].output
    op_options(name, args)  # before anything is read or written
    check_output(args.output, [args.input], force=args.force, suffixes=None if kind == "bytes" else WRITABLE)
    for path, suffixes, what in extra:
        if path:
            check_output(path, [args.input], force=args.force, suffixes=suffixes, what=what)
    mesh = read_input(args.input)
    out, metrics, seconds = run_op(name, mesh, args, run)
    Path(args.output).write_bytes(out) if kind == "bytes" else write_output(args.output, out)
    return mesh, out, metrics, seconds
