"""``fill_holes(mesh, fill_border=True)`` on every raw scan: time per scan and what became of each loop.

The raw scans: the bunny's range scans (``scans/*.ply``), ``bunny_scan.ply`` of the meshes folder and the
dragon's (``scans-dragon/*.ply``). Each scan is filled once after a warm-up call (the compiled kernels
and the solver loaded), from arrays (the whole-mesh analysis included); wall clock and the process's CPU
time. Per scan: loops filled, left open (each named in the report, with why), and the loop lengths.

Run: ``.venv/bin/python benchmarks/bench_fill_holes_border.py [--out NAME.md]`` (about a minute).
"""

from __future__ import annotations

import argparse
import os
import time
import warnings

import numpy as np
from _common import DATA, markdown_table, write_markdown

from o3d_lsmesh.holes import fill_holes_arrays

SCANS = [
    *sorted((DATA.parent / "scans").glob("*.ply")),
    *([DATA / "bunny_scan.ply"] if (DATA / "bunny_scan.ply").exists() else []),
    *sorted((DATA.parent / "scans-dragon").glob("*.ply")),
]


def main() -> int:
    import open3d as o3d

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="fill_holes_border.md")
    args = parser.parse_args()
    rows, load = [], os.getloadavg()[0]
    fill_holes_arrays(*(np.asarray(a) for a in _pyramid()), fill_border=True)  # warm-up
    for path in SCANS:
        mesh = o3d.io.read_triangle_mesh(str(path))
        V, T = np.asarray(mesh.vertices), np.asarray(mesh.triangles).astype(np.int64)
        wall, cpu = time.perf_counter(), time.process_time()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            out = fill_holes_arrays(V, T, fill_border=True)
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        holes = out.report.holes
        left = [h for h in holes if not h.filled]
        rows.append(
            (
                path.name,
                len(T),
                len(holes),
                max((h.edges for h in holes), default=0),
                len(holes) - len(left),
                len(left),
                f"{wall:.2f}",
                f"{cpu:.2f}",
            )
        )
        print(*rows[-1], flush=True)
    table = markdown_table(
        [
            "scan",
            "triangles",
            "loops",
            "longest loop (edges)",
            "filled",
            "left open (reported)",
            "wall s",
            "CPU s",
        ],
        rows,
    )
    walls = [float(r[6]) for r in rows]
    summary = (
        f"{len(rows)} scans; wall time per scan: max {max(walls):.2f} s, median {float(np.median(walls)):.2f} s, "
        f"total {sum(walls):.1f} s. The machine was shared with other jobs (2 cores; load average "
        f"{load:.1f} at the start, {os.getloadavg()[0]:.1f} at the end; OMP_NUM_THREADS="
        f"{os.environ.get('OMP_NUM_THREADS', 'unset')}): wall times are inflated by the others' work, CPU "
        "time less so (it sums the time of every thread of the call)."
    )
    write_markdown(
        args.out,
        "Filling every loop of the raw scans (fill_border=True)",
        [("Method", __doc__.split(chr(10) * 2)[1]), ("Summary", summary), ("Per scan", table)],
    )
    return 0


def _pyramid():
    return (
        np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 1]], float),
        np.array([[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]]),
    )


if __name__ == "__main__":
    raise SystemExit(main())
