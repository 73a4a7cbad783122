"""What every subcommand shares: the parser classes, argument types, output policy and error mapping."""

from __future__ import annotations

import argparse
import contextlib
import dis
import inspect
import json
import math
import os
import re
import sys
import textwrap
import traceback
import warnings
from collections.abc import Sequence
from typing import Any, Callable

from .._batch_ops import WRITABLE, jsonable

PROG = "o3d-lsmesh"


class CLIError(Exception):
    """A user error: reported as one line on stderr with exit code 2."""


class PictureError(Exception):
    """A picture that could not be drawn (no working renderer): one line on stderr, exit code 1."""


# --------------------------------------------------------------------------- parser


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


def add_command(
    sub: Any,
    common: argparse.ArgumentParser,
    handler: Callable[[argparse.Namespace, Run], int],
    arguments: dict[str, str],
) -> argparse.ArgumentParser:
    """Add the subcommand ``handler.__name__`` with its positional ``arguments`` (name: help).

    ``--help`` is the handler's docstring: its first line the summary, its last
    paragraph (``example: ...``) the example, the paragraphs between the
    description.
    """
    summary, *body, example = inspect.cleandoc(handler.__doc__ or "").split("\n\n")
    parser = sub.add_parser(
        handler.__name__,
        parents=[common],
        help=summary.rstrip("."),
        description="\n\n".join(textwrap.fill(" ".join(p.split()), 79) for p in body),
        epilog=f"example:\n  {PROG} {handler.__name__} {example.removeprefix('example: ')}",
    )
    for name, text in arguments.items():
        parser.add_argument(name, metavar=name.upper(), help=text)
    parser.set_defaults(handler=handler, positionals=tuple(arguments))
    return parser


def bounded(
    kind: Callable[[str], Any], minimum: float, description: str, maximum: float | None = None
) -> Callable[[str], Any]:
    """An argparse type for finite ``kind`` numbers in ``[minimum, maximum]``, with a one-line error naming the rule."""

    def parse(text: str) -> Any:
        try:
            value = kind(text)
        except ValueError:
            value = math.nan
        if not minimum <= value < math.inf:  # (nan fails too)
            article = "an" if description[0] in "aeiou" else "a"
            raise argparse.ArgumentTypeError(f"must be {article} {description}, got {text!r}")
        if maximum is not None and value > maximum:
            raise argparse.ArgumentTypeError(f"must be at most {maximum:,}, got {text!r}")
        return value

    return parse


positive_int = bounded(int, 1, "positive integer")
nonnegative_int = bounded(int, 0, "non-negative integer")
nonnegative_float = bounded(float, 0, "non-negative finite number")


def shape_change_text(change: dict) -> str:
    """One line for :func:`~o3d_lsmesh.metrics.shape_change`: a closed mesh's volume change, an open one's inward
    shift along the normals (its volume about the origin means nothing)."""
    if change["closed"]:
        percent = change["volume_change_percent"]
        return "volume change " + ("n/a (input volume 0)" if percent is None else f"{percent:+.3f}%")
    if change["inward_shift_mean"] is None:
        return "open surface (no volume; no vertex correspondence for a shift)"
    rim, interior = (change[f"inward_shift_{key}"] for key in ("rim", "interior"))
    return (
        f"open surface (no volume): inward shift along the normals {change['inward_shift_mean']:.4g} "
        f"(rim {'n/a' if rim is None else f'{rim:.4g}'}, interior {'n/a' if interior is None else f'{interior:.4g}'})"
    )


def mesh_suffix(text: str) -> str:
    """An argparse type for an output format (``ply`` or ``.ply``); ``.glb`` is refused with the way out."""
    suffix = "." + text.lstrip(".").lower()
    if suffix not in WRITABLE:
        raise argparse.ArgumentTypeError(
            f"must be one of {', '.join(WRITABLE)}{glb_hint(suffix)}, got {text!r}"
        )
    return suffix


def glb_hint(suffix: str) -> str:
    return " (Open3D writes .glb files it cannot read back: use .gltf)" if suffix == ".glb" else ""


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

#: API parameters whose CLI flag has another name; every other option's flag is its parameter's name.
_FLAG_OF = {
    "number_of_iterations": "iterations",
    "unknown_vertex_indices": "unknown",
    "number_of_points": "points",
}
#: Phrases of library messages that name an API option, and the CLI words the user typed instead.
_PHRASES = (
    (r"smooth_boundary=False", "--fixed-boundary"),
    (r"must be None for method='(\w+)'", r"cannot be used with --method \1"),
    (r"method='(\w+)' or '(\w+)'", r"--method \1 or \2"),
    (r"method='(\w+)'", r"--method \1"),
    (r"\(outside unknown_vertex_indices\)", "(outside --unknown)"),
    (r"\bbuild_hierarchy\b", "the hierarchy"),
)


def cli_words(text: str, args: argparse.Namespace | None) -> str:
    """A library message in the words of the command line: ``--count`` for ``count``, ``INPUT 'scan.ply'`` for ``mesh``.

    A message of the library's checks starts "<parameter> must ..." (or "mesh
    ..." about the input mesh); the parameter becomes the option of the same
    name, or the positional argument (the file the user named).
    """
    positionals = getattr(args, "positionals", ())

    def spell(api_name: str) -> str:
        name = _FLAG_OF.get(api_name, api_name)
        if name == "mesh" and "input" in positionals:
            name = "input"
        if name in positionals:
            return f"{name.upper()} {getattr(args, name)!r}"
        return "--" + name.replace("_", "-") if hasattr(args, name) else api_name

    text = re.sub(r"^(mesh)\b|(?<![\w.-])([a-z][a-z_]*)(?= must\b)", lambda m: spell(m[1] or m[2]), text)
    for pattern, replacement in _PHRASES:
        text = re.sub(pattern, replacement, text)
    return text


def is_user_error(error: BaseException) -> bool:
    """Whether ``error`` is one the library raised on purpose (a ``raise`` statement in o3d_lsmesh).

    A ``ValueError`` or ``TypeError`` from numpy, Open3D or a slip in our own
    code (a bad format string) is an internal error and must show its
    traceback, not pass as the user's fault.
    """
    from .._errors import SingularSystemError

    if isinstance(error, SingularSystemError):
        return True
    tb = error.__traceback__
    if tb is None:
        return False
    while tb.tb_next is not None:
        tb = tb.tb_next
    code = tb.tb_frame.f_code
    package = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    if not os.path.abspath(code.co_filename).startswith(package + os.sep):
        return False
    # the instruction that raised: an explicit `raise` statement, not an operation failing
    return any(i.offset == tb.tb_lasti and i.opname == "RAISE_VARARGS" for i in dis.get_instructions(code))


def close_progress_bars() -> None:
    """End every live tqdm bar with its newline, so that an error message starts on a line of its own.

    A bar left open by an exception (held alive by the traceback) would otherwise
    have the message printed after its last ``\\r``, on the bar's line.
    """
    tqdm_module = sys.modules.get("tqdm.std")
    for bar in list(getattr(getattr(tqdm_module, "tqdm", None), "_instances", ())):
        with contextlib.suppress(Exception):
            bar.close()


def fail(text: str, code: int) -> int:
    close_progress_bars()
    sys.stdout.flush()
    print(text if text.startswith(PROG) else f"{PROG}: error: {text}", file=sys.stderr, flush=True)
    return code


def internal_error(error: BaseException) -> int:
    close_progress_bars()
    traceback.print_exception(type(error), error, error.__traceback__, file=sys.stderr)
    return fail(f"{PROG}: internal error (a bug in o3d-lsmesh, not in your input: please report it)", 1)


def _show_warning(message: Warning | str, category: type[Warning], *_args: Any, **_kwargs: Any) -> None:
    from .._progress import write

    write(f"{PROG}: warning: {message}")


def run_handler(parser: argparse.ArgumentParser, argv: Sequence[str] | None) -> int:
    """Parse ``argv``, run its subcommand and map what it raises to an exit code and a message."""
    args = None
    try:
        with warnings.catch_warnings():
            # a warning is one line naming the program, printed above the bar, not a source line
            # of the package or of the console script in the middle of it
            warnings.showwarning = _show_warning
            args = parser.parse_args(argv)
            return int(args.handler(args, Run(args)))
    except CLIError as error:
        return fail(str(error), 2)
    except (ValueError, TypeError) as error:
        if not is_user_error(error):
            return internal_error(error)
        # the library's own checks: the message names the parameter, what was expected and what came
        return fail(cli_words(str(error), args), 2)
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
