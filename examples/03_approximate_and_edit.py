"""03 - Approximate a mesh with few control points, then edit it by moving them.
=============================================================================

A least-squares mesh (Sorkine and Cohen-Or 2004) is the smoothest geometry of
a given connectivity that passes near a few control points. Chosen greedily
(each new control point where the current LS mesh is farthest from the
original), about 2% of the vertices approximate the shape; the kept Cholesky
factor then turns every edit of the control points into one
back-substitution.

    python examples/03_approximate_and_edit.py
    python examples/03_approximate_and_edit.py mesh.ply --count 300 --out pictures
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import open3d as o3d

from o3d_lsmesh import LSMeshSolver, approximate, render
from o3d_lsmesh.app.shapes import demo_mesh


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    parser.add_argument("mesh", nargs="?", help="a triangle mesh file (default: built-in blob)")
    parser.add_argument(
        "--count", type=int, default=None, help="control points (default 2%% of the vertices)"
    )
    parser.add_argument("--out", help="folder for the picture")
    args = parser.parse_args(argv)

    mesh = o3d.io.read_triangle_mesh(args.mesh) if args.mesh else demo_mesh(5)
    vertices = np.asarray(mesh.vertices)
    count = args.count or max(1, round(0.02 * len(vertices)))
    size = np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0))

    start = time.perf_counter()
    approximation, indices = approximate(mesh, count, method="greedy")
    seconds = time.perf_counter() - start
    error = np.linalg.norm(np.asarray(approximation.vertices) - vertices, axis=1)
    print(f"input: {len(vertices)} vertices; {count} greedy control points in {seconds:.2f} s")
    print(
        f"approximation error / bounding-box diagonal: max {error.max() / size:.5f}, RMS {np.sqrt(np.mean(error**2)) / size:.5f}"
    )

    # The same system as approximate(): solve() reproduces its result, and edits reuse the factor.
    start = time.perf_counter()
    solver = LSMeshSolver(mesh, indices)
    factor_seconds = time.perf_counter() - start
    same = np.abs(solver.solve() - np.asarray(approximation.vertices)).max()

    # Edit: lift the control points of the top 20% (by height) by 15% of the diagonal.
    positions = vertices[indices].copy()
    height = positions[:, 2]
    handles = height >= np.percentile(height, 80)
    lift = 0.15 * size
    positions[handles, 2] += lift
    start = time.perf_counter()
    edited = solver.mesh(positions)
    edit_seconds = time.perf_counter() - start

    moved = np.asarray(edited.vertices) - np.asarray(approximation.vertices)
    achieved = moved[indices[handles], 2].mean()
    low = vertices[:, 2] < np.percentile(vertices[:, 2], 20)
    print(f"solver.solve() vs approximate(): max difference {same:.2e}")
    print(
        f"edit: {handles.sum()} handles lifted by {lift:.4f}; they moved {achieved:.4f} on average "
        f"(soft constraints, weight 1); the bottom 20% moved {np.linalg.norm(moved[low], axis=1).mean():.2e}"
    )
    print(
        f"factor {factor_seconds * 1000:.1f} ms, each edit {edit_seconds * 1000:.1f} ms "
        f"({factor_seconds / max(edit_seconds, 1e-9):.1f}x faster than refactoring)"
    )

    if args.out:
        Path(args.out).mkdir(parents=True, exist_ok=True)
        path = Path(args.out) / "03_approximate_and_edit.png"
        render(
            [mesh, approximation, edited],
            path,
            width=360,
            height=360,
            view_direction=(1.0, -0.6, 0.3),
            up=(0, 0, 1),
            titles=["input", f"{count} control points", "edited"],
        )
        print(f"picture: {path} (input | {count}-point approximation | edited)")
    return 0


if __name__ == "__main__":
    main()  # (no sys.exit: the docs gallery runs this file in its own process)
