"""07 - Fill holes with patches faired as least-squares meshes.
===============================================================

Scans have holes (occlusions, grazing angles, dark spots). ``fill_holes``
closes each one: a minimum-weight triangulation of the hole's loop (Liepa
2003), refined to the density of the edges around it, whose new vertices are
then placed as a least-squares mesh with the surrounding rings as anchors
(Sorkine and Cohen-Or 2004, section 6). Here geodesic disks are cut from a
surface whose true shape is known, filled with continuity 0 (a membrane), 1
(the LS-mesh energy) and 2 (tri-Laplacian, the default), and the fills are
measured against the removed surface. A scan's outer border stays open.

    python examples/07_fill_holes.py
    python examples/07_fill_holes.py horse.ply --radius 10 --out pictures
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import open3d as o3d
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from o3d_lsmesh import fill_holes, render
from o3d_lsmesh.app.shapes import demo_mesh


def cut_disk(mesh, centre: int, radius: float):
    """The mesh without the triangles within geodesic (edge-path) ``radius`` of vertex ``centre``."""
    V, T = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
    e = np.concatenate([T[:, [0, 1]], T[:, [1, 2]], T[:, [2, 0]]])
    graph = coo_matrix(
        (np.linalg.norm(V[e[:, 0]] - V[e[:, 1]], axis=1), (e[:, 0], e[:, 1])), shape=(len(V),) * 2
    )
    inside = dijkstra(graph.tocsr(), directed=False, indices=centre, limit=radius * 1.01) < radius
    holed = o3d.geometry.TriangleMesh(mesh)
    holed.remove_triangles_by_mask(inside[T].any(axis=1))
    holed.remove_unreferenced_vertices()
    return holed


def crop_ball(mesh, centre, radius):
    """The triangles of ``mesh`` whose vertices all lie within ``radius`` of ``centre``."""
    V, T = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
    inside = np.linalg.norm(V - centre, axis=1) < radius
    part = o3d.geometry.TriangleMesh(mesh)
    part.remove_triangles_by_mask(~inside[T].all(axis=1))
    part.remove_unreferenced_vertices()
    return part


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    parser.add_argument("mesh", nargs="?", help="a closed triangle mesh file (default: built-in surface)")
    parser.add_argument("--radius", type=float, default=6.0, help="hole radius in mean edge lengths")
    parser.add_argument("--out", help="folder for the picture")
    args = parser.parse_args(argv)

    mesh = o3d.io.read_triangle_mesh(args.mesh) if args.mesh else demo_mesh(4)
    V, T = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
    h = float(np.linalg.norm(V[T[:, 0]] - V[T[:, 1]], axis=1).mean())
    # two holes on opposite sides: the vertices furthest along +x and -y
    holed = cut_disk(mesh, int(np.argmax(V[:, 0])), args.radius * h)
    holed = cut_disk(holed, int(np.argmin(np.asarray(holed.vertices)[:, 1])), args.radius * h)
    truth = o3d.t.geometry.RaycastingScene()
    truth.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
    print(
        f"input: {len(V)} vertices, mean edge h = {h:.4g}; two holes of radius {args.radius:g} h "
        f"({len(holed.triangles)} triangles left)"
    )
    print("continuity  new vertices  mean distance to truth (h)  max (h)  closed  time (ms)")
    filled = None
    for continuity in (0, 1, 2):
        start = time.perf_counter()
        out = fill_holes(holed, continuity=continuity)
        seconds = time.perf_counter() - start
        new = np.asarray(out.vertices)[len(holed.vertices) :]
        d = truth.compute_distance(o3d.core.Tensor(new.astype(np.float32))).numpy() / h
        print(
            f"{continuity:10d}  {len(new):12d}  {d.mean():26.4f}  {d.max():7.3f}  {out.is_watertight()!s:6s}"
            f"  {1000 * seconds:9.1f}"
        )
        filled = out
    print(
        f"signed volume: input {mesh.get_volume() if mesh.is_watertight() else float('nan'):.5g}, "
        f"filled {filled.get_volume():.5g}"
    )

    if args.out:
        Path(args.out).mkdir(parents=True, exist_ok=True)
        path = Path(args.out) / "07_fill_holes.png"
        # the neighbourhood of the first hole, looked at from outside along its normal
        centre = V[int(np.argmax(V[:, 0]))]
        normal = np.asarray(mesh.compute_vertex_normals().vertex_normals)[int(np.argmax(V[:, 0]))]
        crop = [crop_ball(m, centre, 3.5 * args.radius * h) for m in (holed, filled)]
        render(
            crop,
            path,
            width=360,
            height=360,
            reference=mesh,
            error_max=0.5 * h,
            view_direction=normal,
            titles=["with holes", "filled (continuity 2)"],
            colorbar_title="distance to the original",
        )
        print(
            f"picture: {path} (holed | filled with continuity 2, colored by distance to the original, "
            "yellow = 0.5 h)"
        )
    return 0


if __name__ == "__main__":
    main()  # (no sys.exit: the docs gallery runs this file in its own process)
