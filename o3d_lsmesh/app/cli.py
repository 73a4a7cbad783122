"""The ``o3d-lsmesh`` command line: the entry point, its parser and the mapping of errors to exit codes.

It imports the commands (:mod:`~o3d_lsmesh.app.commands`), which import their kit
(:mod:`~o3d_lsmesh.app.cli_kit`), never back. Docs: ``docs/cli.rst``.
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
from functools import partial
from importlib.metadata import PackageNotFoundError, version
from typing import Any

from ..core.errors import InputError
from ..core.progress import Progress, close_all
from .cli_kit import PROG, Parser, PictureError, Run, add_command, add_option
from .commands import approximate, batch, compare, decode, demo, denoise, encode, fill, hierarchy, reconstruct
from .files import WRITABLE, CLIError, mesh_suffix
from .ops import OPS, RUN_FLAGS, Option, choice, flag, int_at_least, number

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
    (``method='local'``) or with the value given (``level=2``) reads ``--method local``, ``--level 2``.
    """
    text, param = str(error), error.param
    spellings = {option.name: option.cli_flag for option in _options(args)} | getattr(args, "flags", {})
    for name, spelled in spellings.items():
        # name=value (a Python literal): the flag and the value as typed; a switch's True: the flag alone
        found = re.compile(rf"\b{re.escape(name)}=(True\b|'[^']*'|[-+.\w]+)")
        text = found.sub(partial(_as_typed, spelled), text)
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


def _as_typed(flag: str, found: re.Match) -> str:
    return flag if found[1] == "True" else f"{flag} {found[1].strip(chr(39))}"


def _options(args: argparse.Namespace | None) -> list[Option]:
    """The options of the command's operation (batch: of its ``--op``'s)."""
    command = getattr(args, "command", None) or ""
    names = str(getattr(args, "op", "") or "") if command == "batch" else command
    return [o for name in names.split(",") if name.strip() in OPS for o in OPS[name.strip()].options]


def _option(args: argparse.Namespace | None, param: str) -> Option | None:
    return next((o for o in _options(args) if param in (o.api_param, o.name)), None)


def fail(text: str, code: int) -> int:
    close_all()
    sys.stdout.flush()
    print(text if text.startswith(PROG) else f"{PROG}: error: {text}", file=sys.stderr, flush=True)
    return code


def _show_warning(message: Warning | str, category: type[Warning], *_args: Any, **_kwargs: Any) -> None:
    Progress.write(f"{PROG}: warning: {message}")


#: the demo scan has up to about 0.55 * resolution**2 vertices: 2000 gives about 2.2 million
MAX_RESOLUTION = 2000
_FILES = {"input": "mesh file", "output": "mesh file to write"}
_GRID = int_at_least(20, MAX_RESOLUTION, "a grid size of at least 20 rays")
#: the demo's flags
DEMO = (
    Option("out", str, "demo_out", "output folder"),
    Option("no_render", flag, False, "skip the picture", is_flag=True),
    Option("resolution", _GRID, 200, "the scanner's grid of R x R rays (200: about 22,000 vertices)"),
    # (beyond 10 spacings the scan is noise; 1e308 overflowed to a NaN vertex)
    Option(
        "noise",
        number(float, 0, 10.0, "a number in [0, 10]"),
        0.3,
        "range noise in grid spacings where the surface faces the scanner (at most 10)",
    ),
    Option("seed", int, 0, "random seed of the noise and dropouts"),
)


def add_parsers(sub: Any, writing: argparse.ArgumentParser, common: argparse.ArgumentParser) -> None:
    """Add every subcommand; ``writing`` adds ``--force`` to ``common`` (not for the demo: it reads no file)."""
    files = {"input": "mesh file to denoise", "output": f"mesh file to write ({', '.join(WRITABLE)})"}
    picture = Option("render", str, help="write a before/after picture (default: none)", metavar="PNG")
    add_command(sub, writing, denoise, files, picture)
    add_command(sub, writing, fill, _FILES)
    help = "also write the control indices, .npy or .txt (default: not written)"
    add_command(sub, writing, approximate, _FILES, Option("indices", str, help=help, metavar="FILE"))
    help = "index file (.npy or text) or list of indices and a:b ranges, e.g. '0:100,250'"
    unknown = Option("unknown", str, help=help, param="unknown_vertex_indices", required=True, metavar="SPEC")
    help = "known vertices as soft constraints (whole mesh re-solved)"
    add_command(sub, writing, reconstruct, _FILES, unknown, Option("soft", flag, False, help, is_flag=True))
    add_command(sub, writing, encode, {"input": "mesh file", "output": "file for the encoded bytes"})
    names = {"mesh": "mesh file the data was encoded on", "data": "file written by encode"}
    anchors = Option("anchors", int_at_least(1), help="use only the first K anchors (default: all)")
    add_command(sub, writing, decode, names | {"output": _FILES["output"]}, anchors)
    names = {"input": "mesh file", "outdir": "folder for level_NN files (created if needed)"}
    help = "file format of the levels (.ply .obj ...)"
    add_command(sub, writing, hierarchy, names, Option("format", mesh_suffix, ".ply", help))
    names = {"a": "first mesh file (the reference)", "b": "second mesh file"}
    help = "write a distance map: A and B side by side, colored by distance to A (default: none)"
    units = Option("units", choice("model", "edge"), "model", "model units or mean edge lengths of A")
    add_command(sub, writing, compare, names, Option("render", str, help=help, metavar="PNG"), units)
    _add_batch(add_command(sub, writing, batch, {}))
    add_command(sub, common, demo, {}, *DEMO)


def _add_batch(p: argparse.ArgumentParser) -> None:
    """``batch``: its own flags (:func:`~o3d_lsmesh.app.batch.run`'s parameters) and every op's options."""
    p.add_argument(
        "inputs", nargs="+", metavar="INPUT", help="files, folders (searched recursively) or globs"
    )
    p.add_argument("outdir", metavar="OUTDIR", help="folder for the outputs and the report")
    operations = ", ".join(f"{name} ({op.help})" for name, op in OPS.items())
    p.description = f"{p.description}\n\n" + textwrap.fill(f"Operations: {operations}.", 79)
    help = "an operation or a pipeline in order, e.g. denoise or denoise,compare"
    p.add_argument("--op", required=True, help=help)
    p.add_argument("--set", action="append", default=[], metavar="OP.NAME=VALUE", help="an option of one op")
    where = p.add_mutually_exclusive_group()
    for option in RUN_FLAGS:
        add_option(where if option.name.startswith("scheduler") else p, option)
    title = "operation options (each applies to every op of the pipeline that has it; --set OP.NAME=VALUE for one op)"
    group = p.add_argument_group(title)
    owners: dict[str, list[tuple[str, Option]]] = {}
    for op in OPS.values():
        for option in op.options:
            owners.setdefault(option.name, []).append((op.name, option))
    for name, pairs in owners.items():
        option = pairs[0][1]
        text = f"{option.help} [{', '.join(n for n, _ in pairs)}]"
        if len({o.help for _, o in pairs}) > 1:
            text = "; ".join(f"{n}: {o.help}" for n, o in pairs)
        # SUPPRESS: an option not given is left to each op's default (and --help shows none); values are
        # parsed per op by batch.run, from the same table
        kwargs: dict[str, Any] = {"action": "store_true"} if option.is_flag else {"metavar": "VALUE"}
        text = text.replace("%", "%%").replace("(default:", "(op default:")
        group.add_argument(
            option.cli_flag, dest=f"opt_{name}", default=argparse.SUPPRESS, help=text, **kwargs
        )
    flags = {name: "--" + name.replace("_", "-") for name in [*owners, "op"]}
    flags |= {option.name: option.cli_flag for option in RUN_FLAGS}
    p.set_defaults(positionals=("inputs", "outdir"), flags=flags)


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
