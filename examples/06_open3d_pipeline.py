"""06 - An Open3D pipeline that chains o3d_lsmesh steps with Open3D's own.
=======================================================================

``o3d_lsmesh.register()`` adds our operations as methods of Open3D's legacy
and tensor ``TriangleMesh`` (explicitly: importing o3d_lsmesh changes
nothing). Each returns a new mesh, so they chain with Open3D's methods:

    mesh.remove_duplicated_vertices().filter_smooth_constrained(10).simplify_quadric_decimation(n)

    python examples/06_open3d_pipeline.py
    python examples/06_open3d_pipeline.py scan.ply --out pictures
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import open3d as o3d

from o3d_lsmesh import register, render, unregister
from o3d_lsmesh.app.metrics import signed_volume
from o3d_lsmesh.app.shapes import add_noise, demo_mesh, mean_edge_length


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    parser.add_argument("mesh", nargs="?", help="a triangle mesh file (default: built-in noisy blob)")
    parser.add_argument("--out", help="folder for the picture")
    args = parser.parse_args(argv)

    if args.mesh:
        mesh = o3d.io.read_triangle_mesh(args.mesh)
    else:
        clean = demo_mesh(5)
        mesh = add_noise(clean, 0.3 * mean_edge_length(clean), seed=3)

    names = register()
    try:
        print(f"registered on both TriangleMesh classes: {', '.join(names)}")
        start = time.perf_counter()
        legacy = (
            mesh.remove_duplicated_vertices()
            .remove_unreferenced_vertices()
            .filter_smooth_constrained(10, reimpose_every=2)
            .simplify_quadric_decimation(target_number_of_triangles=len(mesh.triangles) // 4)
            .filter_smooth_constrained(5)
        )
        legacy.compute_vertex_normals()
        print(
            f"legacy pipeline: {len(mesh.vertices)} -> {len(legacy.vertices)} vertices in "
            f"{time.perf_counter() - start:.2f} s; volume {signed_volume(mesh):.4f} -> {signed_volume(legacy):.4f}"
        )

        # The same on a tensor mesh: device and dtypes are kept.
        tensor = o3d.t.geometry.TriangleMesh.from_legacy(mesh)
        start = time.perf_counter()
        tensor_out = tensor.filter_smooth_constrained(10, reimpose_every=2).simplify_quadric_decimation(
            target_reduction=0.75
        )
        print(
            f"tensor pipeline: {tensor.vertex.positions.shape[0]} -> {tensor_out.vertex.positions.shape[0]} vertices "
            f"in {time.perf_counter() - start:.2f} s on {tensor_out.device}, positions {tensor_out.vertex.positions.dtype}"
        )

        # Least-squares steps chain too: approximate from 2% control points, then restore a patch.
        approx = mesh.filter_smooth_constrained(10).approximate_ls(max(1, len(mesh.vertices) // 50))
        top = np.flatnonzero(
            np.asarray(approx.vertices)[:, 2] > np.percentile(np.asarray(approx.vertices)[:, 2], 95)
        )
        restored = approx.reconstruct_geometry(top)
        error = np.linalg.norm(np.asarray(restored.vertices) - np.asarray(approx.vertices), axis=1)
        print(
            f"approximate_ls + reconstruct_geometry: {len(top)} vertices rebuilt, max change {error.max():.2e}"
        )
    finally:
        unregister()
    print(
        f"after unregister(): hasattr(mesh, 'filter_smooth_constrained') = {hasattr(mesh, 'filter_smooth_constrained')}"
    )

    if args.out:
        Path(args.out).mkdir(parents=True, exist_ok=True)
        path = Path(args.out) / "06_open3d_pipeline.png"
        render(
            [mesh, legacy, tensor_out],
            path,
            width=360,
            height=360,
            view_direction=(0.3, 0.4, 1.0),
            titles=["input", "legacy pipeline", "tensor pipeline"],
        )
        print(f"picture: {path} (input | legacy pipeline | tensor pipeline)")
    return 0


if __name__ == "__main__":
    main()  # (no sys.exit: the docs gallery runs this file in its own process)
