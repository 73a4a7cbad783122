"""Errors by class: a user's bad input raises ``InputError``/``InputTypeError`` naming its parameter.

The command line maps an :class:`~o3d_lsmesh.core.errors.InputError` to its flag by ``param`` and shows
any other exception as a bug (a traceback). So a plain ``raise ValueError(...)`` or ``raise TypeError(...)``
in the package's Python source must be an internal invariant, listed below with its reason; the compiled
kernels (``.pyx``) keep ``ValueError`` (reached only through a bug) and are not walked.
"""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

import o3d_lsmesh
from o3d_lsmesh.app.files import write_atomic
from o3d_lsmesh.app.ops import BatchOp, Option, int_at_least
from o3d_lsmesh.app.shapes import demo_mesh
from o3d_lsmesh.core.connectivity import Connectivity
from o3d_lsmesh.core.errors import InputError, SingularSystemError
from o3d_lsmesh.lsmesh import reconstruct_geometry

PACKAGE = Path(o3d_lsmesh.__file__).parent

#: (module path below o3d_lsmesh/, enclosing function) -> why a plain ValueError/TypeError is right there
ALLOWED = {
    # internal invariants: every caller passes arrays that core.validate.mesh_arrays checked
    ("core/connectivity.py", "Connectivity.__init__"): "triangles of shape (m, 3)",
    ("core/operators.py", "scan_normal_matrix"): "mesh_arrays refuses a triangle with a repeated corner",
    # the dense branch keeps cho_factor's ValueError on a non-finite system: callers assemble finite ones
    ("core/solve.py", "solve_spd"): "a non-finite system",
    # an internal object asked for the part it was built without: a bug of its caller
    ("fairing/barycenter.py", "LocalOperator.constant"): "built with keep_constraint=False",
    # argparse's type-function protocol: the CLI turns the ValueError into an ArgumentTypeError naming the
    # flag, batch.run into an InputError naming the option (app/batch.py)
    ("app/ops.py", "number.parse"): "option parser",
    ("app/ops.py", "choice.parse"): "option parser",
    ("app/ops.py", "flag"): "option parser",
    ("app/ops.py", "count_or_percent"): "option parser",
    ("app/ops.py", "levels_spec"): "option parser",
    ("app/ops.py", "folder"): "option parser",
    ("app/files.py", "mesh_suffix"): "option parser (--format)",
}


def _plain_raises(path: Path) -> list[tuple[str, int]]:
    """``(enclosing function's qualified name, line)`` of each ``raise ValueError``/``TypeError`` in ``path``."""
    found: list[tuple[str, int]] = []

    def walk(node: ast.AST, scope: tuple[str, ...]) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                walk(child, (*scope, child.name))
                continue
            if isinstance(child, ast.Raise) and child.exc is not None:
                target = child.exc.func if isinstance(child.exc, ast.Call) else child.exc
                if isinstance(target, ast.Name) and target.id in ("ValueError", "TypeError"):
                    found.append((".".join(scope) or "<module>", child.lineno))
            walk(child, scope)

    walk(ast.parse(path.read_text(encoding="utf-8"), str(path)), ())
    return found


def test_no_plain_value_or_type_error_outside_the_allowed_internal_sites():
    seen, unexpected = set(), []
    for path in sorted(PACKAGE.rglob("*.py")):
        module = path.relative_to(PACKAGE).as_posix()
        for scope, line in _plain_raises(path):
            if (module, scope) in ALLOWED:
                seen.add((module, scope))
            else:
                unexpected.append(f"o3d_lsmesh/{module}:{line} in {scope}")
    assert not unexpected, (
        "a user's bad input must raise InputError/InputTypeError(param=...) (o3d_lsmesh.core.errors); "
        "an internal invariant goes into ALLOWED with its reason: " + ", ".join(unexpected)
    )
    assert seen == set(ALLOWED), f"ALLOWED lists sites that no longer raise: {set(ALLOWED) - seen}"


def test_the_walker_finds_plain_raises_and_skips_input_errors(tmp_path):
    source = tmp_path / "m.py"
    source.write_text(
        "class A:\n    def f(self):\n        raise ValueError('x')\n"
        "def g():\n    raise InputError('y', param='y')\n"
        "def h():\n    if 1:\n        raise TypeError\n"
    )
    assert _plain_raises(source) == [("A.f", 3), ("h", 8)]


def _batch_op(**fields):
    return lambda: BatchOp("x", lambda mesh, options, context: (mesh, {}), **fields)


@pytest.mark.parametrize(
    "call, param, match",
    [
        (
            lambda: Connectivity(np.zeros((0, 3), np.int64), 2**31).adjacency,
            "mesh",
            "fewer than 2\\*\\*31 vertices",
        ),
        (_batch_op(output="png"), "output", "output must be one of"),
        (_batch_op(output="bytes", extension="bin"), "extension", "extension must start with '.'"),
        (_batch_op(options=(Option("suffix", int_at_least(0), 1),)), "options", "option name 'suffix'"),
        (
            lambda: reconstruct_geometry(demo_mesh(1), np.arange(len(demo_mesh(1).vertices))),
            "unknown_vertex_indices",
            "known vertex",
        ),
    ],
)
def test_the_converted_checks_name_their_parameter(call, param, match):
    with pytest.raises(InputError, match=match) as caught:
        call()
    assert caught.value.param == param


def test_a_control_vertex_missing_from_a_component_names_the_indices():
    mesh = demo_mesh(1)
    vertices, triangles = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
    two = (np.vstack([vertices, vertices + 10.0]), np.vstack([triangles, triangles + len(vertices)]))
    with pytest.raises(SingularSystemError) as caught:
        o3d_lsmesh.ls_mesh(two, [0], progress=False)
    assert caught.value.param == "constraint_vertex_indices"


def test_an_output_leading_out_of_outdir_is_an_input_error(tmp_path):
    (tmp_path / "out").mkdir()
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "out" / "sub").symlink_to(tmp_path / "elsewhere")
    with pytest.raises(InputError, match="inside OUTDIR") as caught:
        write_atomic(
            b"x", tmp_path / "out" / "sub" / "a.bin", kind="bytes", suffix=".bin", root=tmp_path / "out"
        )
    assert caught.value.param == "outdir" and list((tmp_path / "elsewhere").iterdir()) == []
