"""Mutation check: remove one rule at a time and name the test that catches it.

Not collected by pytest and not run by ``make test`` (minutes of CPU): run it by
hand after changing a validation rule or the tests of one::

    python tests/mutation_check.py            # every mutant, the real meshes absent
    python tests/mutation_check.py --with-data  # the same with O3D_LSMESH_DATA/SCANS as set
    python tests/mutation_check.py --only laplacian

The mutants: the cotangent Laplacian's uniform fallback for rows it cannot
normalize (``laplacian.py``), and every ``raise`` of ``core/validate.py`` and of
the adapter's mesh reader (``_o3d/__init__.py``: the mesh kind, a tensor mesh without
positions), each replaced by ``pass``. Each runs against a copy of the package in a temporary
folder, first on the test files that own the rule, then (if it survives) on a
wider set. By default the real meshes are absent (``O3D_LSMESH_DATA`` and
``O3D_LSMESH_SCANS`` point nowhere), so a rule must be caught by the tests that
generate their meshes. Prints a Markdown table ``mutation | caught by`` and
exits 1 if a mutant survives.
"""

from __future__ import annotations

import argparse
import ast
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
#: the test files that own each module's rules, then the wider net for a survivor
FIRST = {
    "o3d_lsmesh/core/validate.py": ["tests/test_validate.py", "tests/test_bad_input.py"],
    "o3d_lsmesh/_o3d/__init__.py": ["tests/test_validate.py", "tests/test_bad_input.py"],
    "o3d_lsmesh/laplacian.py": ["tests/test_laplacian.py"],
}
WIDER = [
    "tests/test_lsmesh.py",
    "tests/test_formats.py",
    "tests/test_defect_soups.py",
    "tests/test_selection.py",
    "tests/test_fairing.py",
    "tests/test_cli.py",
]


@dataclass
class Mutant:
    name: str
    path: str  # relative to the repository
    first: int  # 1-based lines first..last are replaced
    last: int
    replacement: list[str]


def _function_of(tree: ast.Module, line: int) -> str:
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.lineno <= line <= (
            node.end_lineno or node.lineno
        ):
            return node.name
    return "<module>"


def raise_mutants(path: str) -> list[Mutant]:
    """Every ``raise`` statement of ``path`` replaced by ``pass`` (line numbers kept)."""
    source = (REPO / path).read_text()
    lines = source.splitlines()
    tree = ast.parse(source)
    mutants = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Raise):
            continue
        first, last = node.lineno, node.end_lineno or node.lineno
        indent = lines[first - 1][: len(lines[first - 1]) - len(lines[first - 1].lstrip())]
        text = " ".join(line.strip() for line in lines[first - 1 : last])
        message = re.sub(r"\s+", " ", text)[len("raise ") :][:70]
        mutants.append(
            Mutant(
                f"{Path(path).name}:{first} {_function_of(tree, first)}: no `{message}`",
                path,
                first,
                last,
                [indent + "pass"] + [""] * (last - first),
            )
        )
    return sorted(mutants, key=lambda m: m.first)


def cotangent_fallback_mutant() -> Mutant:
    """``if degenerate.any():`` of the cotangent Laplacian never taken: no uniform fallback."""
    path = "o3d_lsmesh/laplacian.py"
    lines = (REPO / path).read_text().splitlines()
    (line,) = [i + 1 for i, text in enumerate(lines) if text.strip() == "if degenerate.any():"]
    indent = lines[line - 1][: len(lines[line - 1]) - len(lines[line - 1].lstrip())]
    return Mutant(
        f"laplacian.py:{line} cotangent_laplacian: no uniform fallback for rows cotangents cannot normalize",
        path,
        line,
        line,
        [indent + "if False:"],
    )


def run_tests(root: Path, files: list[str], env: dict) -> tuple[bool, list[str]]:
    """(all passed, the failing test ids) of ``files`` under ``root``."""
    result = subprocess.run(
        [sys.executable, "-m", "pytest", "-p", "no:dash", "-q", "-rf", "--tb=no", "-x", *files],
        cwd=root,
        env=env,
        capture_output=True,
        text=True,
    )
    failed = re.findall(r"^(?:FAILED|ERROR) (\S+)", result.stdout, flags=re.M)
    if result.returncode not in (0, 1):  # collection error, crash, usage error
        failed = failed or [f"pytest exit {result.returncode}"]
    return result.returncode == 0, failed


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--with-data", action="store_true", help="keep O3D_LSMESH_DATA/SCANS as set")
    parser.add_argument(
        "--only",
        action="append",
        default=[],
        help="run the mutants whose name contains this text (repeatable)",
    )
    parser.add_argument("--skip-baseline", action="store_true", help="do not first run the unmutated tests")
    args = parser.parse_args(argv)

    mutants = [
        cotangent_fallback_mutant(),
        *raise_mutants("o3d_lsmesh/core/validate.py"),
        *raise_mutants("o3d_lsmesh/_o3d/__init__.py"),
    ]
    mutants = [m for m in mutants if not args.only or any(text in m.name for text in args.only)]
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1")
    env.pop("PYTHONPATH", None)
    if not args.with_data:
        env["O3D_LSMESH_DATA"] = env["O3D_LSMESH_SCANS"] = "/nonexistent"

    rows, survivors = [], 0
    with tempfile.TemporaryDirectory(prefix="o3d_lsmesh_mutants_") as folder:
        root = Path(folder)
        ignore = shutil.ignore_patterns("__pycache__", "*.c")
        shutil.copytree(REPO / "o3d_lsmesh", root / "o3d_lsmesh", ignore=ignore)
        shutil.copytree(REPO / "tests", root / "tests", ignore=ignore)
        for name in ("pyproject.toml", "README.md"):  # test_cli reads the README's help text
            shutil.copy(REPO / name, root / name)
        env["PYTHONPATH"] = str(root)

        baseline = sorted({f for m in mutants for f in FIRST[m.path]} | set(WIDER))
        passed, failed = (True, []) if args.skip_baseline else run_tests(root, baseline, env)
        if not passed:
            print(f"the unmutated suite fails ({failed}); fix it first", file=sys.stderr)
            return 2

        for mutant in mutants:
            target = root / mutant.path
            original = target.read_text()
            lines = original.splitlines()
            lines[mutant.first - 1 : mutant.last] = mutant.replacement
            target.write_text("\n".join(lines) + "\n")
            start = time.perf_counter()
            try:
                passed, failed = run_tests(root, FIRST[mutant.path], env)
                if passed:
                    passed, failed = run_tests(root, WIDER, env)
            finally:
                target.write_text(original)
            seconds = time.perf_counter() - start
            caught = "SURVIVED" if passed else ", ".join(f"`{f}`" for f in failed[:2])
            survivors += passed
            rows.append((mutant.name, caught))
            print(f"{'survived' if passed else 'caught  '} {seconds:5.1f} s  {mutant.name}", file=sys.stderr)

    print("| mutation | caught by |\n| --- | --- |")
    for name, caught in rows:
        print(f"| {name.replace('|', '/')} | {caught} |")
    print(
        f"\n{len(rows) - survivors} of {len(rows)} mutants caught",
        "(real meshes absent)" * (not args.with_data),
    )
    return 1 if survivors else 0


if __name__ == "__main__":
    sys.exit(main())
