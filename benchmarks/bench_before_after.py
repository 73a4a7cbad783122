"""Old main against new main, side by side in one run: the same public calls, their outputs and their CPU time.

Each case runs in a fresh process of each tree (``--before`` a checkout of the old main with its kernels
built in place, ``--after`` this one), alternating, ``--repeat`` times; it prints the median CPU
seconds of ``import o3d_lsmesh``, and the table those of the first call in a fresh process (lazy
imports and the kernels' first use included) and of a warm call (the best of three more), each ratio
after/before, and the
largest difference between the two outputs (0 means bit-identical: every quality figure computed from
them is unchanged).

    python benchmarks/bench_before_after.py --before /path/to/old/checkout [--repeat 5]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
DATA = Path(os.environ.get("O3D_LSMESH_DATA", HERE.parent.parent / "shared" / "data" / "meshes"))
SCANS = Path(os.environ.get("O3D_LSMESH_SCANS", HERE.parent.parent / "shared" / "data" / "scans"))

# name -> (mesh file, code run on `mesh` with `np`, `o3d`, `o3d_lsmesh` in scope; it sets `out`)
CASES = {
    "constrained_fairing default (scan bun000)": (
        SCANS / "bun000.ply",
        "out = o3d_lsmesh.constrained_fairing(mesh)",
    ),
    "constrained_fairing local x10 (bunny)": (
        DATA / "bunny.ply",
        "out = o3d_lsmesh.constrained_fairing(mesh, 10, method='local')",
    ),
    "constrained_fairing global (bunny)": (
        DATA / "bunny.ply",
        "out = o3d_lsmesh.constrained_fairing(mesh, 2, method='global')",
    ),
    "constrained_fairing features (bunny)": (
        DATA / "bunny.ply",
        "out = o3d_lsmesh.constrained_fairing(mesh, method='features')",
    ),
    "multiresolution_fairing level 2 (bunny)": (
        DATA / "bunny.ply",
        "out = o3d_lsmesh.multiresolution_fairing(mesh, 2, number_of_iterations=5)",
    ),
    "fill_holes 8 holes (horse)": (
        DATA / "horse.ply",
        "mesh.remove_triangles_by_index(np.flatnonzero(np.isin(np.asarray(mesh.triangles),"
        " np.arange(0, len(mesh.vertices), len(mesh.vertices) // 8)).any(axis=1)))\n"
        "out = o3d_lsmesh.fill_holes(mesh)",
    ),
    "ls_mesh 2% controls (horse)": (
        DATA / "horse.ply",
        "out = o3d_lsmesh.ls_mesh(mesh, np.arange(0, len(mesh.vertices), 50))",
    ),
    "build_hierarchy (bunny)": (
        DATA / "bunny.ply",
        "h = o3d_lsmesh.build_hierarchy(mesh)\nout = h.level(len(h) // 2)",
    ),
    "encode + decode 100 anchors (bunny)": (
        DATA / "bunny.ply",
        "out = o3d_lsmesh.decode_geometry(mesh, o3d_lsmesh.encode_geometry(mesh, 100))",
    ),
    "topology_summary (scan bun000)": (
        SCANS / "bun000.ply",
        "out = o3d_lsmesh.topology_summary(mesh)",
    ),
}

WORKER = """
import json, os, sys, time, warnings
sys.path.insert(0, sys.argv[1])
import numpy as np, open3d as o3d
start = time.process_time()
import o3d_lsmesh
imported = time.process_time() - start
assert o3d_lsmesh.__file__.startswith(sys.argv[1]), o3d_lsmesh.__file__
code = sys.argv[3]
warnings.simplefilter("ignore")
cpu = []
# OpenBLAS's threads busy-wait for a fixed time after the library loads (numpy's and SciPy's, at import):
# without this pause that spin lands in whichever call comes first, so a faster import showed as a slower
# first call (benchmarks/results/before_after.md)
time.sleep(1.0)
for _ in range(4):  # the first call (lazy imports, first use of the kernels), then three warm ones
    mesh = o3d.io.read_triangle_mesh(sys.argv[2])
    start = time.process_time()
    exec(code)
    cpu.append(time.process_time() - start)
if isinstance(out, dict):
    np.savez(sys.argv[4], s=np.array(json.dumps(out, sort_keys=True, default=str)))
elif isinstance(out, o3d.geometry.TriangleMesh):
    np.savez(sys.argv[4], v=np.asarray(out.vertices), t=np.asarray(out.triangles))
else:
    np.savez(sys.argv[4], v=np.asarray(out), t=np.zeros(0))
print(json.dumps({"import": imported, "first": cpu[0], "warm": min(cpu[1:])}))
"""


def run(tree: Path, mesh: Path, code: str, out: Path) -> dict[str, float]:
    result = subprocess.run(
        [sys.executable, "-c", WORKER, str(tree), str(mesh), code, str(out)],
        capture_output=True,
        text=True,
        check=True,
        cwd=tempfile.gettempdir(),  # neither tree on the path but the one given
        env={**os.environ, "PYTHONPATH": ""},
    )
    return json.loads(result.stdout.strip().splitlines()[-1])


def difference(a: Path, b: Path) -> float:
    import numpy as np

    x, y = np.load(a), np.load(b)
    if "s" in x.files:  # a dict of figures, as JSON text
        return 0.0 if str(x["s"]) == str(y["s"]) else float("inf")
    if x["t"].shape != y["t"].shape or not np.array_equal(x["t"], y["t"]) or x["v"].shape != y["v"].shape:
        return float("inf")
    return float(np.abs(x["v"] - y["v"]).max()) if x["v"].size else 0.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", type=Path, required=True, help="checkout of the old main, kernels built")
    parser.add_argument("--after", type=Path, default=HERE.parent)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--only", nargs="*", help="case names containing one of these words")
    args = parser.parse_args()
    rows = []
    import_times: dict[str, list[float]] = {"before": [], "after": []}
    with tempfile.TemporaryDirectory() as scratch:
        for name, (mesh, code) in CASES.items():
            if args.only and not any(word in name for word in args.only):
                continue
            if not mesh.exists():
                print(f"skipping {name}: {mesh} not found (set O3D_LSMESH_DATA / O3D_LSMESH_SCANS)")
                continue
            times: dict[str, list[dict]] = {"before": [], "after": []}
            outs = {side: Path(scratch) / f"{side}.npz" for side in times}
            for _ in range(args.repeat):  # alternate, so that a busy spell weighs on both
                for side, tree in (("before", args.before), ("after", args.after)):
                    times[side].append(run(tree.resolve(), mesh, code, outs[side]))
            for side in ("before", "after"):
                import_times[side] += [t["import"] for t in times[side]]
            row = [name]
            for kind in ("first", "warm"):
                before, after = (statistics.median(t[kind] for t in times[s]) for s in ("before", "after"))
                row += [before, after, after / before]
            row.append(difference(outs["before"], outs["after"]))
            rows.append(row)
            print(" ".join(str(round(x, 4)) if isinstance(x, float) else x for x in row), flush=True)
    before, after = (statistics.median(import_times[s]) for s in ("before", "after"))
    print(f"\nimport o3d_lsmesh, CPU s (median over every process): before {before:.3f}, after {after:.3f}")
    print(
        "\n| case | first call: before | after | ratio | warm call: before | after | ratio | largest output difference |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for name, *figures, diff in rows:
        cells = " | ".join(f"{x:.3f}" if i % 3 != 2 else f"{x:.2f}" for i, x in enumerate(figures))
        print(f"| {name} | {cells} | {diff:.3g} |")


if __name__ == "__main__":
    main()
