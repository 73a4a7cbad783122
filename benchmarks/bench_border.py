"""The outer-border rule of ``find_holes`` (``BORDER_FACING_AWAY``) on data it was not chosen on.

A component's longest loop is its outer border when less than a quarter of the component's area faces
away from the loop's vector area or sideways (a cosine below 0.2). The quarter is not fitted: it is
where a sphere missing a cap of a third of its area stands, between a one-sided view (nothing faces
away) and a closed surface with a small hole (about half faces away). Here it is scored on every raw scan (bunny and dragon: each
component of at least a tenth of the scan's area must keep its silhouette open) and on geodesic holes of
2.5h, 6h and 15h around three seeded centres in every closed shared mesh, and the real loops of the
open shared meshes (each must be a hole). The fraction is computed here by plain NumPy, apart from
the module.

Run: ``.venv/bin/python benchmarks/bench_border.py`` (about a minute).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from _common import DATA, load_mesh, markdown_table, write_markdown
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components, dijkstra

from o3d_lsmesh.holes import BORDER_FACING_AWAY, find_holes

SCANS = [Path(os.environ.get("O3D_LSMESH_SCANS", DATA.parent / "scans")), DATA.parent / "scans-dragon"]


def facing_away(V, T, loop, component):
    """Area fraction of the component's triangles whose normal points against the loop's vector area or
    sideways (cosine below 0.2)."""
    p = V[loop] - V[loop[0]]
    normal = 0.5 * np.cross(p, np.roll(p, -1, axis=0)).sum(axis=0)
    q = V[T[component]]
    vector = 0.5 * np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0])
    size = np.linalg.norm(vector, axis=1)
    return float(size[vector @ (normal / np.linalg.norm(normal)) < 0.2 * size].sum() / size.sum())


def judged(V, T, wanted_area=0.1):
    """(fraction facing away, taken as border) of each component's longest loop, components of at least
    ``wanted_area`` of the mesh's area."""
    n = len(V)
    e = np.concatenate([T[:, [0, 1]], T[:, [1, 2]], T[:, [2, 0]]])
    _, label = connected_components(
        coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n)), directed=False
    )
    tri_label = label[T[:, 0]]
    area = 0.5 * np.linalg.norm(np.cross(V[T[:, 1]] - V[T[:, 0]], V[T[:, 2]] - V[T[:, 0]]), axis=1)
    comp_area = np.bincount(tri_label, weights=area)
    out = []
    holes = find_holes(V, T)
    for c in np.flatnonzero(comp_area >= wanted_area * area.sum()):
        mine = [h for h in holes if h.component == c]
        if mine:
            longest = max(mine, key=lambda h: h.perimeter)
            out.append((facing_away(V, T, longest.vertices, tri_label == c), longest.border))
    return out


def cut(V, T, centre, radius):
    e = np.concatenate([T[:, [0, 1]], T[:, [1, 2]], T[:, [2, 0]]])
    w = np.linalg.norm(V[e[:, 0]] - V[e[:, 1]], axis=1)
    graph = coo_matrix((w, (e[:, 0], e[:, 1])), shape=(len(V), len(V))).tocsr()
    inside = dijkstra(graph, directed=False, indices=centre, limit=radius * 1.01) < radius
    return T[~inside[T].any(axis=1)]


def main() -> int:
    import open3d as o3d

    rows = []
    for folder in SCANS:
        for path in sorted(folder.glob("*.ply")):
            mesh = o3d.io.read_triangle_mesh(str(path))
            V, T = np.asarray(mesh.vertices), np.asarray(mesh.triangles).astype(np.int64)
            for fraction, border in judged(V, T):
                rows.append(("raw scan", path.name, "silhouette", fraction, border, border))
    rng = np.random.default_rng(2026)
    for name in sorted(p.name for p in DATA.glob("*.ply")):
        mesh = load_mesh(name)
        V, T = np.asarray(mesh.vertices), np.asarray(mesh.triangles).astype(np.int64)
        if name in ("bunny_scan.ply", "dragon.ply", "plane_holes.ply", "bun_zipper.ply"):
            continue  # a raw scan, a marching-cubes soup, a plane (its rim is a border), a copy of bunny
        if len(find_holes(V, T)) == 0:
            h = np.linalg.norm(V[T[:, 0]] - V[T[:, 1]], axis=1).mean()
            for radius in (2.5, 6.0, 15.0):
                for centre in rng.integers(len(V), size=3):
                    holed = cut(V, T, int(centre), radius * h)
                    for fraction, border in judged(V, holed, 0.5):
                        rows.append(("closed, cut", name, f"{radius:g}h", fraction, border, False))
        else:
            for fraction, border in judged(V, T, 0.5):
                rows.append(("open mesh", name, "its loops", fraction, border, False))
    box = o3d.geometry.TriangleMesh.create_box().subdivide_midpoint(4)
    V, T = np.asarray(box.vertices), np.asarray(box.triangles).astype(np.int64)
    centre = V[T].mean(axis=1)
    top = (np.abs(centre[:, 2] - 1) < 1e-12) & (np.linalg.norm(centre[:, :2] - 0.5, axis=1) < 0.2)
    for fraction, border in judged(V, T[~top], 0.5):
        rows.append(("closed, cut", "a unit box", "hole in its top", fraction, border, False))
    table = markdown_table(
        ["kind", "mesh", "loop", "facing away", "taken as border", "right"],
        [(k, m, loop, f"{f:.3f}", b, b == want) for k, m, loop, f, b, want in rows],
    )
    summary = markdown_table(
        ["kind", "loops", "facing away: min", "max", "judged right"],
        [
            (
                kind,
                len(group),
                f"{min(r[3] for r in group):.3f}",
                f"{max(r[3] for r in group):.3f}",
                f"{sum(r[4] == r[5] for r in group)} / {len(group)}",
            )
            for kind in ("raw scan", "closed, cut", "open mesh")
            if (group := [r for r in rows if r[0] == kind])
        ],
    )
    print(summary)
    write_markdown(
        "border.md",
        "The outer-border rule on data it was not chosen on",
        [
            (
                "Rule",
                f"`BORDER_FACING_AWAY = {BORDER_FACING_AWAY}`. {__doc__.split(chr(10) * 2)[1]}",
            ),
            ("Summary", summary),
            ("Every judged loop", table),
        ],
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
