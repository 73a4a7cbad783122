"""The default denoiser under load: ``constrained_fairing(mesh)`` on a ~40k-vertex raw scan, timed on a
quiet machine and beside two competing busy processes (``python -c "while 1: pass"``).

A parallel region whose threads spin at its barriers waits a whole time slice whenever the scheduler
has parked one of its threads behind another job; the target is a loaded median within 2x of the quiet one
on two cores. Each configuration runs in a fresh interpreter (OpenMP reads its environment when it loads):
the defaults, libgomp's default spinning waits (before), and ``OMP_NUM_THREADS=1``. Results in
``results/under_load.md``.

    python benchmarks/bench_under_load.py [--repeat 7] [--scan bun000.ply]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

from _common import REPO, markdown_table, write_markdown

SCANS = Path(os.environ.get("O3D_LSMESH_SCANS", REPO.parent / "shared" / "data" / "scans"))

#: a fresh interpreter per configuration: loads the scan, warms up, then times one call per line read
CHILD = """
import sys, time, open3d as o3d
from o3d_lsmesh import constrained_fairing
mesh = o3d.io.read_triangle_mesh(sys.argv[1])
options = dict(method="local") if sys.argv[2] == "local" else {}
constrained_fairing(mesh, **options)
print("ready", flush=True)
for _ in sys.stdin:
    start = time.perf_counter()
    constrained_fairing(mesh, **options)
    print(time.perf_counter() - start, flush=True)
"""

#: the defaults, libgomp's own spinning waits (what the package had before it chose passive ones), one thread
CONFIGURATIONS = (
    ("threads (default)", {}),
    ("threads, GOMP_SPINCOUNT=300000 (before)", {"GOMP_SPINCOUNT": "300000"}),
    ("OMP_NUM_THREADS=1", {"OMP_NUM_THREADS": "1"}),
)


def measure(path: Path, method: str, repeat: int) -> dict[str, dict[int, list[float]]]:
    """``{configuration: {busy processes: wall times}}``: rounds of one call per configuration, quiet then
    beside two spinning processes, so that whatever else the machine runs weighs on every column alike."""
    children = {}
    for label, environ in CONFIGURATIONS:
        child = subprocess.Popen(
            [sys.executable, "-c", CHILD, str(path), method],
            env={**os.environ, **environ},
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        assert child.stdout is not None and child.stdout.readline().strip() == "ready"
        children[label] = child
    times: dict[str, dict[int, list[float]]] = {label: {0: [], 2: []} for label in children}
    try:
        for _ in range(repeat):
            for busy in (0, 2):
                spinners = [subprocess.Popen([sys.executable, "-c", "while 1: pass"]) for _ in range(busy)]
                try:
                    time.sleep(0.2 * busy)  # the spinners running before the clock starts
                    for label, child in children.items():
                        assert child.stdin is not None and child.stdout is not None
                        child.stdin.write("go\n")
                        child.stdin.flush()
                        times[label][busy].append(float(child.stdout.readline()))
                finally:
                    for spinner in spinners:
                        spinner.kill()
                        spinner.wait()
    finally:
        for child in children.values():
            child.kill()
            child.wait()
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=7)
    parser.add_argument("--scan", default="bun000.ply")
    args = parser.parse_args()
    path = SCANS / args.scan
    if not path.exists():
        print(f"skipping: {path} not found (set O3D_LSMESH_SCANS)")
        return
    load = os.getloadavg()[0]
    rows = []
    for method in ("default", "local"):
        for label, measured in measure(path, method, args.repeat).items():
            quiet, loaded = statistics.median(measured[0]), statistics.median(measured[2])
            rows.append(
                [
                    method,
                    label,
                    f"{quiet:.3f}",
                    f"{loaded:.3f}",
                    f"{max(measured[2]):.3f}",
                    f"{loaded / quiet:.2f}",
                ]
            )
            print(rows[-1], flush=True)
    table = markdown_table(
        ["method", "threads", "quiet median (s)", "loaded median (s)", "loaded worst (s)", "loaded / quiet"],
        rows,
    )
    write_markdown(
        "under_load.md",
        f"Default denoiser under load ({args.scan}, {os.cpu_count()} cores)",
        [
            (
                f"Wall time of one call, median of {args.repeat} after a warm-up; loaded = beside two busy processes",
                table
                + f"\n\nTarget: loaded within 2x of quiet. The machine's other work was not stopped (load average "
                f"{load:.1f} at the start): configurations alternate within each round, so it weighs on all alike.",
            )
        ],
    )


if __name__ == "__main__":
    main()
