"""05 - Compact geometry encoding and progressive decoding.
========================================================

The geometry-aware bases paper (Sorkine, Cohen-Or, Irony, Toledo) stores a
mesh's geometry as a few anchors: their indices and quantized positions. The
receiver, who has the connectivity, solves a least-squares mesh through them.
Anchors arrive in the order they were chosen (greedy: largest error first),
so every prefix of the stream is already a good mesh, and each refinement is
a rank-k update of the kept factor, not a new factorization.

    python examples/05_progressive_decoding.py
    python examples/05_progressive_decoding.py mesh.ply --count 500 --out pictures
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import open3d as o3d

from o3d_lsmesh import decode_geometry, encode_geometry, iter_decode_geometry, render
from o3d_lsmesh.app.shapes import demo_mesh


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    parser.add_argument("mesh", nargs="?", help="a triangle mesh file (default: built-in blob)")
    parser.add_argument("--count", type=int, default=None, help="anchors (default 3%% of the vertices)")
    parser.add_argument("--bits", type=int, default=12)
    parser.add_argument("--out", help="folder for the picture")
    args = parser.parse_args(argv)

    mesh = o3d.io.read_triangle_mesh(args.mesh) if args.mesh else demo_mesh(4)
    truth = np.asarray(mesh.vertices)
    n = len(truth)
    count = args.count or max(1, round(0.03 * n))
    size = np.linalg.norm(truth.max(axis=0) - truth.min(axis=0))

    start = time.perf_counter()
    data = encode_geometry(mesh, count, bits=args.bits)
    print(
        f"input: {n} vertices; {count} anchors at {args.bits} bits -> {len(data)} bytes "
        f"({8 * len(data) / n:.2f} bits per vertex) in {time.perf_counter() - start:.2f} s"
    )
    print(f"(uncompressed float32 positions: {12 * n} bytes)")

    step = max(1, count // 6)
    print(f"{'anchors':>8s} {'max error / diag':>17s} {'RMS / diag':>11s}")
    snapshots = []
    start = time.perf_counter()
    for k, decoded in enumerate(iter_decode_geometry(mesh, data, step=step), start=1):
        used = min(k * step, count)
        error = np.linalg.norm(np.asarray(decoded.vertices) - truth, axis=1)
        print(f"{used:8d} {error.max() / size:17.5f} {np.sqrt(np.mean(error**2)) / size:11.5f}")
        snapshots.append(decoded)
    print(f"progressive decoding: {len(snapshots)} meshes in {time.perf_counter() - start:.2f} s")
    full = decode_geometry(mesh, data)
    gap = np.abs(np.asarray(full.vertices) - np.asarray(snapshots[-1].vertices)).max()
    print(f"last progressive mesh vs one-shot decode: max difference {gap:.2e}")

    if args.out:
        Path(args.out).mkdir(parents=True, exist_ok=True)
        path = Path(args.out) / "05_progressive_decoding.png"
        picks = [snapshots[0], snapshots[len(snapshots) // 2], snapshots[-1], mesh]
        render(
            picks,
            path,
            width=300,
            height=300,
            reference=mesh,
            view_direction=(0.3, 0.4, 1.0),
            titles=["first decoded", "halfway", "last decoded", "original"],
            colorbar_title="distance to the original",
        )
        print(
            f"picture: {path} (first, middle, last decoded | original; colored by distance to the original)"
        )
    return 0


if __name__ == "__main__":
    main()  # (no sys.exit: the docs gallery runs this file in its own process)
