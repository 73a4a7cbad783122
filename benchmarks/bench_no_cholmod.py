"""The SciPy path against CHOLMOD: the README tour and ``approximate(bunny_scan, 500)`` (issue #41).

Each run is a fresh process; "without scikit-sparse" hides it from the import (the default install,
warning included). Wall and CPU seconds, medians of ``--repeat`` runs; the warnings a user sees.
``--before DIR`` also times the ``o3d_lsmesh`` in ``DIR`` (an export of an earlier commit, with its
compiled extensions) on ``--before-tasks``, one run each (the old SciPy path takes minutes).

Run: .venv/bin/python benchmarks/bench_no_cholmod.py [--repeat 3] [--before DIR]
Writes benchmarks/results/no_cholmod.md.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _common import DATA, REPO, markdown_table, write_markdown

MESH = DATA / "bunny_scan.ply"
WARNING = "scikit-sparse is not importable"
NOTES = """\
"before" is the package of an earlier commit (`--before`; here 88c106c, whose SciPy path refactored at
every update) with this checkout's compiled kernels; its tour was not rerun (one run takes 20-40 min
here; issue #41 measured 1,112 s against CHOLMOD's 53 s, and 7 warnings). CPU is the process's time on
all its threads, the steadier figure on a shared machine: the 2 cores' load varied from 3 to 11 during
these runs, so wall times (and their ratio) move with it. "warnings shown" counts the SciPy fallback's
warning on the process's stderr. The second table is why the SciPy path solves with one BLAS thread
(`single_threaded_blas`): with OpenBLAS's threads a solve of several columns costs up to 10x more per
column (bunny_scan past 4 columns, igea from 2)."""


def child(task: str, without: bool, package: str | None) -> None:
    if package:  # before _common's checkout on sys.path
        sys.path.insert(0, package)
    if without:
        sys.modules["sksparse"] = None  # type: ignore[assignment]  # import fails as if not installed
    import open3d as o3d

    import o3d_lsmesh

    mesh = o3d.io.read_triangle_mesh(str(MESH))
    start_wall, start_cpu = time.perf_counter(), time.process_time()
    if task == "approximate":
        o3d_lsmesh.approximate(mesh, 500)
    else:
        text = (REPO / "README.md").read_text()
        code = text.split("```python\n", 1)[1].split("```", 1)[0]
        code = code.replace(
            'o3d.io.read_triangle_mesh("scan.ply")', f"o3d.io.read_triangle_mesh({str(MESH)!r})"
        )
        with tempfile.TemporaryDirectory() as tmp:
            code = code.replace('"before_after.png"', repr(str(Path(tmp) / "before_after.png")))
            exec(compile(code, "README.md", "exec"), {})
    wall, cpu = time.perf_counter() - start_wall, time.process_time() - start_cpu
    print(json.dumps({"wall": wall, "cpu": cpu, "package": o3d_lsmesh.__file__}))


def solve_widths(name: str, threads: bool, widths=(1, 2, 4, 6, 8, 16)) -> list:
    """SuperLU's solve CPU milliseconds per column by columns per call (best of 3) on ``name``'s LS-mesh
    normal matrix, with OpenBLAS's threads or one (``single_threaded_blas``, as the SciPy path solves)."""
    import contextlib

    import open3d as o3d
    import scipy.sparse as sp

    from o3d_lsmesh._o3d import read_mesh
    from o3d_lsmesh.core._iterative import splu_spd as _splu_spd
    from o3d_lsmesh.core.solve import single_threaded_blas
    from o3d_lsmesh.laplacian import laplacian_matrix

    data = read_mesh(o3d.io.read_triangle_mesh(str(DATA / name)), weld=True)
    L = laplacian_matrix(data.vertices, data.triangles).tocsc()
    n = L.shape[0]
    lu = _splu_spd((L.T @ L + sp.identity(n)).tocsc())
    row = [f"{name} ({n})", "OpenBLAS threads" if threads else "one thread"]
    with contextlib.nullcontext() if threads else single_threaded_blas():
        for width in widths:
            rhs = np.asfortranarray(np.random.default_rng(0).random((n, width)))
            best = np.inf
            for _ in range(3):
                start = time.process_time()
                lu.solve(rhs)
                best = min(best, time.process_time() - start)
            row.append(1000.0 * best / width)
    return row


def run(task: str, without: bool, package: str | None) -> dict:
    env = dict(os.environ)
    env.pop("O3D_LSMESH_NO_CHOLMOD", None)
    flags = (["--without"] if without else []) + (["--before", package] if package else [])
    out = subprocess.run(
        [sys.executable, __file__, "--child", task, *flags],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    result = json.loads(out.stdout.strip().splitlines()[-1])
    result["warnings"] = out.stderr.count(WARNING)
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--child", choices=("approximate", "tour"))
    parser.add_argument("--without", action="store_true")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--tasks", nargs="+", default=["approximate", "tour"])
    parser.add_argument("--before", help="a directory holding an earlier o3d_lsmesh to time too")
    parser.add_argument("--before-tasks", nargs="+", default=["approximate"])
    args = parser.parse_args()
    if args.child:
        return child(args.child, args.without, args.before)
    if not MESH.exists():
        sys.exit(f"{MESH} not found (set O3D_LSMESH_DATA)")
    rows = []
    plan = [(task, "this checkout", None, args.repeat) for task in args.tasks]
    if args.before:
        plan = [(task, "before", args.before, 1) for task in args.before_tasks] + plan
    for task, label, package, repeat in plan:
        medians = {}
        for without in (False, True):
            runs = [run(task, without, package) for _ in range(repeat)]
            print(task, "without" if without else "with", runs, flush=True)
            medians[without] = {key: float(np.median([r[key] for r in runs])) for key in ("wall", "cpu")}
            medians[without]["warnings"] = max(r["warnings"] for r in runs)
        with_, without_ = medians[False], medians[True]
        rows.append(
            [
                task,
                f"{label} ({repeat} run{'s' if repeat > 1 else ''})",
                with_["wall"],
                with_["cpu"],
                without_["wall"],
                without_["cpu"],
                without_["cpu"] / with_["cpu"],
                without_["warnings"],
            ]
        )
    table = markdown_table(
        [
            "task",
            "code",
            "CHOLMOD wall s",
            "CHOLMOD CPU s",
            "without scikit-sparse wall s",
            "without CPU s",
            "CPU ratio",
            "warnings shown",
        ],
        rows,
    )
    widths = markdown_table(
        ["mesh (unknowns)", "BLAS", *(f"{w} column{'s' if w > 1 else ''}" for w in (1, 2, 4, 6, 8, 16))],
        [solve_widths(name, threads) for name in ("bunny_scan.ply", "igea.ply") for threads in (True, False)],
    )
    write_markdown(
        "no_cholmod.md",
        "Without scikit-sparse: SciPy's splu with low-rank updates against CHOLMOD",
        [
            ("bunny_scan.ply (39,977 vertices), medians over the runs", table),
            ("SuperLU solve: CPU ms per column by columns per call (best of 3)", widths),
            ("Notes", NOTES),
        ],
    )


if __name__ == "__main__":
    main()
