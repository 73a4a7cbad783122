"""Volume-cost hierarchy (issues 4, 13) against fast-simplification, and multiresolution fairing by scale.

1. For every level of ``build_hierarchy`` on bunny, horse, camel and igea, and
   fast-simplification run (from the input, fresh) to the same triangle count:
   two-sided Hausdorff and mean surface distance to the input (in % of the
   bounding-box diagonal), volume change in %, smallest angle and share of
   triangles with an angle under 10 degrees, manifoldness, Euler characteristic
   and boundary loops, and time (ours: cumulative time of the levels so far).
2. Speed: the whole hierarchy down to 1% of the vertices against
   fast-simplification run once to the same triangle count, on Igea (134k),
   the horse Loop-subdivided three times (1.27M) and four times (5.1M),
   interleaved rounds, one thread each (our kernel is one sequential loop;
   fast-simplification is single-threaded); wall time and the calling
   thread's CPU time (the machine is shared), and the peak memory above the
   baseline of each call (RSS sampled every 2 ms). The bunny's whole hierarchy
   to 100 vertices is timed too.
3. Multiresolution fairing by scale: the tables of ``bench_multiresolution.py``
   (levels 0..6 on the bunny, the horse and a generated blob; read them with
   the notes of ``benchmarks/results/multiresolution.md``).

Run: ``.venv/bin/python benchmarks/bench_hierarchy.py [--quick] [--speed]`` (``--speed``: the speed table only,
printed).
"""

from __future__ import annotations

import ctypes
import sys
import threading
import time

import fast_simplification
import numpy as np
import psutil
from _common import load_mesh, markdown_table, timed, write_markdown

from o3d_lsmesh.hierarchy import build_hierarchy
from o3d_lsmesh.hierarchy import hierarchy as tuning
from o3d_lsmesh.hierarchy.collapse import collapse_levels
from o3d_lsmesh.hierarchy.hierarchy import build_hierarchy_arrays
from o3d_lsmesh.metrics import (
    signed_volume,
    surface_distance,
    topology_summary,
    triangle_angles,
)

QUICK = "--quick" in sys.argv
SAMPLES = 20_000 if QUICK else 50_000


def level_times(V, F, min_vertices=100):
    """Cumulative wall time after each level, from the kernel's report after each level (as build_hierarchy)."""
    start = time.perf_counter()
    times = [0.0]
    collapse_levels(
        V,
        F,
        alpha=tuning.ALPHA,
        beta=tuning.BETA,
        max_normal_angle=tuning.MAX_NORMAL_ANGLE,
        min_quality=tuning.MIN_QUALITY,
        max_tries=tuning.MAX_TRIES,
        min_vertices=min_vertices,
        report=lambda _: times.append(time.perf_counter() - start),
    )
    return times


def describe(V, F, V0, F0, vol0, diag):
    d = surface_distance((V0, F0), (V, F), number_of_points=SAMPLES)
    ang = triangle_angles((V, F))
    topo = topology_summary((V, F))
    manifold = "y" if topo["vertex_manifold"] else ("edge" if topo["edge_manifold"] else "n")
    return {
        "haus": 100 * d["hausdorff"] / diag,
        "mean": 100 * d["mean"] / diag,
        "vol": 100 * (signed_volume((V, F)) - vol0) / abs(vol0),
        "min_angle": ang["min_angle"],
        "under10": 100 * ang["share_under_10"],
        "manifold": manifold,
        "topo": f"{topo['euler']}/{topo['boundary_loops']}",
    }


def compare(name):
    mesh = load_mesh(name + ".ply")
    if mesh is None:
        return None, None
    V0 = np.asarray(mesh.vertices).copy()
    F0 = np.asarray(mesh.triangles).astype(np.int64)
    diag = float(np.linalg.norm(V0.max(0) - V0.min(0)))
    vol0 = signed_volume((V0, F0))
    h, t_total = timed(lambda: build_hierarchy((V0, F0)), repeat=1 if QUICK else 3)
    cumulative = level_times(V0, F0)
    rows = []
    worse_volume = 0
    compared = 0
    for i in range(1, len(h)):
        V, F = h.level_arrays(i)
        ours = describe(V, F, V0, F0, vol0, diag)
        (Vf, Ff), t_fs = timed(
            lambda: fast_simplification.simplify(V0, F0.astype(np.int32), target_count=len(F))
        )
        Ff = Ff.astype(np.int64)
        used = np.unique(Ff)
        remap = np.zeros(len(Vf), dtype=np.int64)
        remap[used] = np.arange(len(used))
        Vf, Ff = Vf[used], remap[Ff]
        fs = describe(Vf, Ff, V0, F0, vol0, diag)
        compared += 1
        worse_volume += abs(ours["vol"]) > abs(fs["vol"])
        rows.append(
            [
                i,
                len(V),
                len(Vf),
                f"{ours['haus']:.3g} / {fs['haus']:.3g}",
                f"{ours['mean']:.3g} / {fs['mean']:.3g}",
                f"{ours['vol']:+.3g} / {fs['vol']:+.3g}",
                f"{ours['min_angle']:.2g} / {fs['min_angle']:.2g}",
                f"{ours['under10']:.3g} / {fs['under10']:.3g}",
                f"{ours['manifold']} / {fs['manifold']}",
                f"{ours['topo']} / {fs['topo']}",
                f"{1000 * cumulative[i]:.0f} / {1000 * t_fs:.0f}",
            ]
        )
    header = [
        "level",
        "V ours",
        "V fs",
        "Hausdorff % diag (ours / fs)",
        "mean dist % diag",
        "volume change %",
        "min angle deg",
        "% tris < 10 deg",
        "manifold",
        "euler/loops",
        "time ms (ours cumul. / fs)",
    ]
    summary = [
        name,
        len(V0),
        len(h),
        h.vertex_count(len(h) - 1),
        f"{t_total:.3f}",
        f"{compared - worse_volume}/{compared}",
    ]
    return (
        f"{name}: {len(V0)} vertices, input euler/loops "
        f"{topology_summary((V0, F0))['euler']}/{topology_summary((V0, F0))['boundary_loops']}",
        markdown_table(header, rows),
    ), summary


try:  # glibc keeps freed blocks below its (growing) mmap threshold in the heap
    _LIBC = ctypes.CDLL("libc.so.6") if sys.platform.startswith("linux") else None
except OSError:
    _LIBC = None


class PeakMemory:
    """Peak resident memory above the starting level while the block runs (sampled every 2 ms), in MB."""

    def __enter__(self):
        self.process = psutil.Process()
        if _LIBC is not None:  # hand freed heap back first: pages reused without a fault would not show
            _LIBC.malloc_trim(0)
        self.base = self.peak = self.process.memory_info().rss
        self.running = True
        self.thread = threading.Thread(target=self._sample, daemon=True)
        self.thread.start()
        return self

    def _sample(self):
        while self.running:
            self.peak = max(self.peak, self.process.memory_info().rss)
            time.sleep(0.002)

    def __exit__(self, *exc):
        self.running = False
        self.thread.join()
        self.peak = max(self.peak, self.process.memory_info().rss)
        self.mb = (self.peak - self.base) / 2**20


def _run(fn):
    with PeakMemory() as memory:
        wall, cpu = time.perf_counter(), time.thread_time()
        result = fn()
        cpu, wall = time.thread_time() - cpu, time.perf_counter() - wall
    return result, wall, cpu, memory.mb


def speed_row(label, V, F, rounds):
    F32 = F.astype(np.int32)
    target = max(len(V) // 100, 100)
    ours, fs = [], []
    h = None
    for _ in range(rounds):  # interleaved, so that a slow spell of the shared machine hits both
        h = None
        h, *o = _run(lambda: build_hierarchy_arrays(V, F, min_vertices=target))
        count = len(h.triangles[-1])
        out, *f = _run(lambda: fast_simplification.simplify(V, F32, target_count=count))
        ours.append(o)
        fs.append(f)
    ours, fs = np.array(ours), np.array(fs)
    best = lambda a, i: a[:, i].min()
    return [
        label,
        len(V),
        len(F),
        len(h),
        f"{h.vertex_count(len(h) - 1)} / {len(np.unique(out[1]))}",
        f"{best(ours, 0):.2f}",
        f"{best(fs, 0):.2f}",
        f"{best(ours, 0) / best(fs, 0):.2f}",
        f"{best(ours, 1):.2f}",
        f"{best(fs, 1):.2f}",
        f"{best(ours, 1) / best(fs, 1):.2f}",
        f"{np.min(ours[:, 1] / fs[:, 1]):.2f} / {np.median(ours[:, 1] / fs[:, 1]):.2f}",
        f"{np.min(ours[:, 0] / fs[:, 0]):.2f} / {np.median(ours[:, 0] / fs[:, 0]):.2f}",
        f"{ours[:, 2].max():.0f}",
        f"{fs[:, 2].max():.0f}",
    ], (ours[:, 0].round(2).tolist(), fs[:, 0].round(2).tolist())


def speed():
    rows, raw = [], []
    bunny = load_mesh("bunny.ply")
    if bunny is not None:
        V, F = np.asarray(bunny.vertices).copy(), np.asarray(bunny.triangles).astype(np.int64)
        runs = [_run(lambda: build_hierarchy_arrays(V, F))[1:3] for _ in range(5)]
        raw.append(
            f"bunny ({len(V)} vertices) whole hierarchy to 100 vertices, best of 5: "
            f"{min(r[0] for r in runs):.3f} s wall, {min(r[1] for r in runs):.3f} s thread CPU"
        )
    igea = load_mesh("igea.ply")
    if igea is not None:
        V, F = np.asarray(igea.vertices).copy(), np.asarray(igea.triangles).astype(np.int64)
        row, times = speed_row("igea", V, F, 3 if QUICK else 5)
        rows.append(row)
        raw.append(f"igea rounds, ours s {times[0]}, fs s {times[1]}")
    horse = load_mesh("horse.ply")
    if horse is not None:
        for k in (1,) if QUICK else (3, 4):
            mesh = horse.subdivide_loop(number_of_iterations=k)
            V, F = np.asarray(mesh.vertices).copy(), np.asarray(mesh.triangles).astype(np.int64)
            del mesh
            row, times = speed_row(f"horse, Loop-subdivided x{k}", V, F, 5 if k <= 3 else 1)
            rows.append(row)
            raw.append(f"horse x{k} rounds, ours s {times[0]}, fs s {times[1]}")
            del V, F
    table = markdown_table(
        [
            "mesh",
            "V",
            "F",
            "levels",
            "V coarsest (ours / fs)",
            "ours wall s",
            "fs wall s",
            "ratio wall",
            "ours thread CPU s",
            "fs thread CPU s",
            "ratio CPU",
            "CPU ratio per round, min / median",
            "wall ratio per round, min / median",
            "ours peak MB",
            "fs peak MB",
        ],
        rows,
    )
    return table + "\n\n" + "\n".join(f"- {line}" for line in raw)


# ------------------------------------------------------------ multiresolution by scale


def scale():
    """The tables of ``bench_multiresolution.py`` (its notes: benchmarks/results/multiresolution.md)."""
    from bench_multiresolution import scale_tables

    return scale_tables()


def main():
    sections, summaries = [], []
    if "--speed" in sys.argv:  # the speed table alone, printed (the results file is left as it is)
        print(speed())
        return
    speed_table = speed()
    print(speed_table, flush=True)
    scale_summary, scale_rows = scale()
    print(scale_summary, flush=True)
    for name in ("bunny", "horse", "camel", "igea"):
        section, summary = compare(name)
        if section is not None:
            sections.append(section)
            summaries.append(summary)
    head = [
        (
            "Whole hierarchy to 1% against one fast-simplification run (same run, interleaved, one thread each)",
            speed_table,
        ),
        ("Multiresolution fairing by scale", scale_summary),
        (
            "Summary of the per-level cross-check",
            markdown_table(
                [
                    "mesh",
                    "V",
                    "levels",
                    "V coarsest",
                    "whole hierarchy s (best of runs)",
                    "levels with |volume change| <= fast-simplification's",
                ],
                summaries,
            ),
        ),
    ]
    notes = (
        "Speed table: rounds of (our `build_hierarchy_arrays` to 1% of the vertices, fast-simplification to our "
        "coarsest triangle count) interleaved; `wall` is the best round's wall time, `thread CPU` the best round's "
        "CPU time of the calling thread (both run in one thread; the machine is shared with other jobs, so CPU time "
        "is the steadier figure); peak MB is the largest rise of the process's resident memory during a call. "
        "Our time includes the lock computation (non-manifold vertices) and the copies of the caller's arrays. "
        "Cross-check tables: our level i against fast-simplification run from the input to the same triangle count "
        "(`target_count` = our level's triangles; its vertex count is shown). Distances are two-sided, sampled "
        f"({SAMPLES} points per side + vertices, RaycastingScene), in % of the bounding-box diagonal. Volume change "
        "is the signed volume against the input's. `manifold`: y = edge- and vertex-manifold, edge = edge-manifold "
        "only, n = neither. `euler/loops`: Euler characteristic / boundary loops (the input's must be kept). Our time "
        "is cumulative over the levels (the kernel's report after each level); fast-simplification's is one fresh run to "
        "that count. Scale tables: see `multiresolution.md` (`benchmarks/bench_multiresolution.py`) for how to read them."
    )
    write_markdown(
        "hierarchy.md",
        "Volume-cost hierarchy vs fast-simplification, multiresolution fairing by scale",
        head
        + [("How to read", notes), ("Multiresolution fairing by scale, every level", scale_rows)]
        + sections,
    )


if __name__ == "__main__":
    main()
