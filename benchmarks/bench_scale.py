"""Scale: LS meshes and global fairing at 1M+ vertices, CHOLMOD against the iterative path.

Run: ``.venv/bin/python benchmarks/bench_scale.py [--sizes 1000000 4000000] [--ops lsmesh,fairing]
[--iterative-only-above N]``. Every (mesh, operation, solver) runs in a fresh subprocess so that its
peak memory (``ru_maxrss``) is its own. Meshes: a seeded noisy UV sphere (the issue's generator) and
a real mesh subdivided (midpoint) to about the same size. Reports time, peak memory, the iterative
path's relative residual and iteration count, and the relative difference ``||X_it - X_chol|| /
||X_chol||`` of the two solutions. Writes ``benchmarks/results/scale.md``.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import tempfile
import time

import numpy as np

from _common import DATA, markdown_table, peak_rss_mb, write_markdown


def noisy_sphere(n: int, seed: int = 0):
    """Seeded noisy UV sphere with about ``n`` vertices (``2 r^2`` for resolution ``r``): (V, F)."""
    import open3d as o3d

    resolution = max(4, int(round(np.sqrt(n / 2.0))))
    mesh = o3d.geometry.TriangleMesh.create_sphere(radius=1.0, resolution=resolution)
    V = np.asarray(mesh.vertices).copy()
    V += np.random.default_rng(seed).normal(scale=0.2 / resolution, size=V.shape)
    return V, np.asarray(mesh.triangles).astype(np.int64)


def subdivided(name: str, n: int):
    """A real mesh midpoint-subdivided until it has at least ``n / 2`` vertices, or None when absent."""
    import open3d as o3d

    path = DATA / name
    if not path.exists():
        return None
    mesh = o3d.io.read_triangle_mesh(str(path))
    while len(mesh.vertices) < n / 2:
        mesh = mesh.subdivide_midpoint(1)
    return np.asarray(mesh.vertices).copy(), np.asarray(mesh.triangles).astype(np.int64)


def make_mesh(kind: str, n: int):
    return noisy_sphere(n) if kind == "noisy sphere" else subdivided("feline.ply", n)


def controls(n: int, fraction: float = 0.02, seed: int = 0) -> np.ndarray:
    return np.sort(np.random.default_rng(seed).choice(n, max(1, int(fraction * n)), replace=False))


def _worker(kind: str, n: int, op: str, solver: str, out: str, queue) -> None:
    import sys

    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    from o3d_lsmesh.fairing.constrained import constrained_fairing_arrays
    from o3d_lsmesh.lsmesh import LSMeshSolver

    V, F = make_mesh(kind, n)
    base = peak_rss_mb()
    start = time.perf_counter()
    residual, iterations = 0.0, 0
    if op == "lsmesh":
        system = LSMeshSolver((V, F), controls(len(V)), solver=solver, _release_arrays=True)
        X = system.solve()
        residual, iterations = system._solver.residual, system._solver.iterations
    else:
        X = constrained_fairing_arrays(V, F, 2, method="global", solver=solver)
    seconds = time.perf_counter() - start
    np.save(out, X)
    queue.put((len(V), seconds, peak_rss_mb(), base, residual, iterations))


def run(kind: str, n: int, op: str, solver: str, out: str):
    ctx = mp.get_context("spawn")
    queue = ctx.Queue()
    proc = ctx.Process(target=_worker, args=(kind, n, op, solver, out, queue))
    proc.start()
    proc.join()
    return queue.get() if proc.exitcode == 0 else None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[1_000_000])
    parser.add_argument("--ops", default="lsmesh,fairing")
    parser.add_argument("--kinds", default="noisy sphere,subdivided feline")
    parser.add_argument("--iterative-only-above", type=int, default=2_000_000,
                        help="sizes above this run the iterative path only (CHOLMOD would not fit)")
    args = parser.parse_args()
    rows = []
    tmp = tempfile.mkdtemp(prefix="bench_scale_")
    for n in args.sizes:
        for kind in args.kinds.split(","):
            for op in args.ops.split(","):
                solvers = ["iterative"] if n > args.iterative_only_above else ["cholmod", "iterative"]
                result = {}
                for solver in solvers:
                    out = os.path.join(tmp, f"{op}_{solver}.npy")
                    got = run(kind, n, op, solver, out)
                    if got is None:
                        print(f"{kind} {n} {op} {solver}: failed")
                        continue
                    result[solver] = got
                    print(kind, op, solver, got, flush=True)
                if not result:
                    continue
                diff = ""
                if len(result) == 2:
                    a = np.load(os.path.join(tmp, f"{op}_cholmod.npy"))
                    b = np.load(os.path.join(tmp, f"{op}_iterative.npy"))
                    diff = float(np.linalg.norm(b - a) / np.linalg.norm(a))
                chol = result.get("cholmod")
                for solver, (vertices, seconds, peak, base, residual, iterations) in result.items():
                    ratio = seconds / chol[1] if chol else ""
                    rows.append([
                        kind, vertices, "LS mesh, 2% controls" if op == "lsmesh" else "global fairing, 2 iterations",
                        solver, seconds, ratio, peak / 1024, (peak - base) / 1024,
                        f"{residual:.1e}" if solver == "iterative" and op == "lsmesh" else "",
                        iterations if solver == "iterative" and op == "lsmesh" else "",
                        f"{diff:.1e}" if solver == "iterative" and diff != "" else "",
                    ])
    table = markdown_table(
        ["mesh", "vertices", "operation", "solver", "time s", "x CHOLMOD", "peak GB", "peak over input GB",
         "rel. residual", "CG its", "rel. diff to CHOLMOD"],
        rows,
    )
    write_markdown(
        "scale.md",
        "Scale: CHOLMOD against the iterative path (PCG + smoothed-aggregation AMG)",
        [("Results", table + "\n\nOne subprocess per row (peak = its ru_maxrss). The machine was shared with "
          "other jobs (load average about 10 on 2 cores): read the ratios, not the seconds.")],
    )


if __name__ == "__main__":
    main()
