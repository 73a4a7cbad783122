"""The ``o3d-lsmesh`` command line: the entry point, its parser and the mapping of errors to exit codes.

It imports the commands (:mod:`~o3d_lsmesh.app.commands`, :mod:`~o3d_lsmesh.app.op_commands`),
which import their kit (:mod:`~o3d_lsmesh.app.cli_kit`), never back. Docs: ``docs/cli.rst``.
"""

from __future__ import annotations

import argparse
import contextlib
import re
import sys
import textwrap
import traceback
import warnings
from collections.abc import Sequence
from importlib.metadata import PackageNotFoundError, version
from typing import Any

from ..core.errors import InputError
from ..core.progress import Progress, close_all
from .cli_kit import PROG, Parser, PictureError, Run
from .commands import add_parsers
from .files import CLIError
from .ops import OPS, Option

__all__ = ["CLIError", "PictureError", "Run", "build_parser", "main"]


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
    close_all()
    sys.stdout.flush()
    print(text if text.startswith(PROG) else f"{PROG}: error: {text}", file=sys.stderr, flush=True)
    return code


def _show_warning(message: Warning | str, category: type[Warning], *_args: Any, **_kwargs: Any) -> None:
    Progress.write(f"{PROG}: warning: {message}")


def build_parser() -> argparse.ArgumentParser:
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
    with contextlib.suppress(PackageNotFoundError):  # (a source tree that was never installed: no --version)
        parser.add_argument("--version", action="version", version=f"{PROG} {version('o3d_lsmesh')}")
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--quiet", action="store_true", help="no progress bars and no report")
    common.add_argument("--json", action="store_true", help="print the metrics as one JSON object on stdout")
    writing = argparse.ArgumentParser(add_help=False, parents=[common])
    writing.add_argument("--force", action="store_true", help="allow overwriting an input file")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser, required=True)
    add_parsers(sub, writing, common)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``o3d-lsmesh`` with ``argv`` (default ``sys.argv[1:]``); return the exit code.

    Exit codes: 0 success, 2 a user error (one line on stderr naming the flag or the file: an
    ``InputError`` is mapped to its flag by ``param``), 1 a picture that could not be drawn or an
    internal error (with its traceback), 130 an interrupt.
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
    except Exception as error:  # a bug: its traceback, below any open bar
        close_all()
        traceback.print_exception(type(error), error, error.__traceback__, file=sys.stderr)
        return fail(f"{PROG}: internal error (a bug in o3d-lsmesh, not in your input: please report it)", 1)
