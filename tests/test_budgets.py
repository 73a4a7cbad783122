"""The redesign's budgets (#36): the package's size, the size of each module, and no private internals.

Counted like a reviewer would: every line of ``.py``, ``.pyx``, ``.pxd`` and ``.pyi`` under ``o3d_lsmesh/``,
docstrings and blanks included (generated C is not source).
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "o3d_lsmesh"
TOTAL_LINES = 13_000
MODULE_LINES = {".py": 500, ".pyx": 900, ".pyi": 500, ".pxd": 500}

# what the package must not reach into: numpy's, SciPy's, Cython's, tqdm's and the interpreter's own
PRIVATE = {
    "numpy's page tuning": r"_set_madvise_hugepage",
    "SciPy's compiled sparse tools": r"_sparsetools",
    "Cython's capsule table": r"__pyx_capi__",
    "tqdm's open-bar registry": r"\b_instances\b",
    "bytecode inspection": r"^\s*(import dis\b|from dis import)|tb_lasti",
    "the interpreter's frames": r"sys\._getframe",
}


def sources() -> list[Path]:
    return sorted(p for p in PACKAGE.rglob("*") if p.suffix in MODULE_LINES and "build" not in p.parts)


def lines(path: Path) -> int:
    return len(path.read_text(encoding="utf-8").splitlines())


def test_sources_are_found() -> None:
    # the budgets below would pass on an empty list
    names = {p.name for p in sources()}
    assert {"__init__.py", "_block_kernel.pyx", "_triangulation_kernel.pyx", "_patch_kernel.pyx"} <= names


# #36 is open on this point: the package is over its budget after the redesign (each module is within its
# own); strict, so that the mark goes as soon as the budget holds
@pytest.mark.xfail(strict=True, reason="the package is over its 13,000-line budget (#36 open)")
def test_package_within_its_line_budget() -> None:
    total = sum(lines(p) for p in sources())
    assert total <= TOTAL_LINES, f"the package has {total} lines, the budget is {TOTAL_LINES}"


@pytest.mark.parametrize("path", sources(), ids=lambda p: str(p.relative_to(PACKAGE)))
def test_module_within_its_line_budget(path: Path) -> None:
    limit = MODULE_LINES[path.suffix]
    assert lines(path) <= limit, (
        f"{path.name} has {lines(path)} lines, a {path.suffix} module at most {limit}"
    )


@pytest.mark.parametrize("what", sorted(PRIVATE))
def test_no_private_internals(what: str) -> None:
    pattern = re.compile(PRIVATE[what], re.MULTILINE)
    found = [str(p.relative_to(PACKAGE)) for p in sources() if pattern.search(p.read_text(encoding="utf-8"))]
    assert not found, f"{what} reached from {found}"


def test_the_private_patterns_match_what_they_name() -> None:
    # each pattern catches the use it is about, so a passing scan means something
    uses = {
        "numpy's page tuning": "np.core.multiarray._set_madvise_hugepage(False)",
        "SciPy's compiled sparse tools": "from scipy.sparse import _sparsetools",
        "Cython's capsule table": "cython_lapack.__pyx_capi__['dpotrf']",
        "tqdm's open-bar registry": 'getattr(tqdm_class, "_instances", ())',
        "bytecode inspection": "import dis",
        "the interpreter's frames": "frame = sys._getframe(1)",
    }
    for what, use in uses.items():
        assert re.search(PRIVATE[what], use, re.MULTILINE), what
