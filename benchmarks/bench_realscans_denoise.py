"""Denoising raw range scans: ``constrained_fairing(mesh)`` with its defaults against every peer's best setting.

Every scan of ``O3D_LSMESH_SCANS`` (the ten Stanford bunny range scans, see
their MANIFEST) is denoised by each peer at every setting of its sweep
(iteration counts; the best per scan is kept, so each peer is scored at the
setting that a user who knew the answer would pick) and by ours with the
defaults, no sweep. Also measured: multiresolution fairing on the scans with
their non-manifold vertices' triangles removed (it refuses non-manifold
input), and the time of the default against Open3D's
``filter_smooth_laplacian`` at its best iteration count, interleaved, at 40k
and about 1.4M vertices (the ten scans as one mesh, midpoint-subdivided once).

Error of a denoised scan = distance from each of its vertices to the
reference surface (``bunny.ply``, Open3D's ``RaycastingScene``), split into
interior and boundary vertices; the signed distance is measured along the
reference's normal at the closest point (positive outside), so that an
inward move (shrinkage) shows as a drop of the signed mean.

``--quick``: the best three peers only (minutes, not 40), to re-check the
targets after a change of ours (``realscans_denoise_quick.md``);
``--speed-only``: the timing section alone (``realscans_denoise_speed.md``).
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
import open3d as o3d
from _common import DATA, REPO, markdown_table, timed, write_markdown

SCANS = Path(os.environ.get("O3D_LSMESH_SCANS", REPO.parent / "shared" / "data" / "scans"))
REFERENCE = "bunny.ply"


def scan_names() -> list[str]:
    return sorted(p.name for p in SCANS.glob("*.ply")) if SCANS.is_dir() else []


def load_scan(name: str):
    mesh = o3d.io.read_triangle_mesh(str(SCANS / name))
    return np.asarray(mesh.vertices).copy(), np.asarray(mesh.triangles).astype(np.int64)


class Reference:
    """Closest-point queries against the reference surface."""

    def __init__(self, path: Path | None = None) -> None:
        mesh = o3d.io.read_triangle_mesh(str(path or DATA / REFERENCE))
        self.scene = o3d.t.geometry.RaycastingScene()
        self.scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))

    def closest(self, points: np.ndarray):
        answer = self.scene.compute_closest_points(o3d.core.Tensor(points.astype(np.float32)))
        return answer["points"].numpy().astype(np.float64), answer["primitive_normals"].numpy().astype(
            np.float64
        )


def boundary_vertices(triangles: np.ndarray, n: int) -> np.ndarray:
    from o3d_lsmesh.topology import boundary_halfedges

    mask = np.zeros(n, dtype=bool)
    mask[boundary_halfedges(triangles, n).ravel()] = True
    return mask


def vertex_normals(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    a, b, c = (vertices[triangles[:, i]] for i in range(3))
    face = np.cross(b - a, c - a)
    normals = np.zeros_like(vertices)
    for i in range(3):
        np.add.at(normals, triangles[:, i], face)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    return normals / np.maximum(length, 1e-300)


#: a triangle is degenerate (near-zero area or a sliver) when 4 sqrt(3) area / (sum of squared edges) is
#: below this (1 for an equilateral triangle; 0.05 is a 1:20 isosceles sliver or a flattened triangle)
DEGENERATE_QUALITY = 0.05


def degenerate_rim_triangles(vertices: np.ndarray, triangles: np.ndarray, boundary: np.ndarray) -> int:
    """Triangles with a boundary vertex whose quality is below ``DEGENERATE_QUALITY``."""
    a, b, c = (vertices[triangles[:, i]] for i in range(3))
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    squares = ((b - c) ** 2).sum(1) + ((c - a) ** 2).sum(1) + ((a - b) ** 2).sum(1)
    quality = 4.0 * np.sqrt(3.0) * area / np.maximum(squares, np.finfo(float).tiny)
    return int(((quality < DEGENERATE_QUALITY) & boundary[triangles].any(axis=1)).sum())


def score(vertices: np.ndarray, triangles: np.ndarray, reference: Reference, boundary: np.ndarray) -> dict:
    """Distances (in micrometres) of the scan's referenced vertices to the reference surface."""
    used = np.zeros(len(vertices), dtype=bool)
    used[triangles.ravel()] = True
    closest, normals = reference.closest(vertices[used])
    offset = vertices[used] - closest
    distance = np.linalg.norm(offset, axis=1) * 1e6
    signed = np.einsum("ij,ij->i", offset, normals) * 1e6
    rim = boundary[used]
    ours = vertex_normals(vertices, triangles)[used]
    angle = np.degrees(np.arccos(np.clip(np.abs(np.einsum("ij,ij->i", ours, normals)), 0.0, 1.0)))
    return {
        "mean": float(distance.mean()),
        "p90": float(np.percentile(distance, 90)),
        "interior": float(distance[~rim].mean()),
        "boundary": float(distance[rim].mean()) if rim.any() else float("nan"),
        "signed": float(signed.mean()),
        "signed_interior": float(signed[~rim].mean()),
        "angle": float(angle.mean()),
        "degenerate": degenerate_rim_triangles(vertices, triangles, boundary),
        "distance": distance,
    }


# ----------------------------------------------------------------------------------------------- peers


def _legacy(vertices, triangles):
    return o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(vertices), o3d.utility.Vector3iVector(triangles)
    )


def _o3d(kind):
    def run(vertices, triangles, k):
        mesh = _legacy(vertices, triangles)
        out = getattr(mesh, f"filter_smooth_{kind}")(number_of_iterations=k)
        return np.asarray(out.vertices)

    return run


def _meshlab(filter_name, **fixed):
    def run(vertices, triangles, k):
        import pymeshlab

        ms = pymeshlab.MeshSet()
        ms.add_mesh(pymeshlab.Mesh(vertex_matrix=vertices, face_matrix=triangles.astype(np.int32)))
        if filter_name == "apply_coord_hc_laplacian_smoothing":
            for _ in range(k):  # HC has no step count: repeat it
                ms.apply_filter(filter_name)
        else:
            ms.apply_filter(filter_name, stepsmoothnum=k, **fixed)
        out = ms.current_mesh().vertex_matrix()
        if len(out) != len(vertices):
            raise RuntimeError(f"{filter_name} changed the vertex count")
        return np.asarray(out, dtype=np.float64)

    return run


def _trimesh(kind):
    def run(vertices, triangles, k):
        import trimesh
        from trimesh import smoothing

        mesh = trimesh.Trimesh(vertices.copy(), triangles.copy(), process=False)
        getattr(smoothing, f"filter_{kind}")(mesh, iterations=k)  # filters work in place
        return np.asarray(mesh.vertices, dtype=np.float64)

    return run


#: every conventional filter with the settings of its sweep (iteration counts)
PEERS = {
    "Open3D simple": (_o3d("simple"), [1, 2, 3, 4, 6]),
    "Open3D Laplacian": (_o3d("laplacian"), [1, 2, 3, 5, 8, 12, 20]),
    "Open3D Taubin": (_o3d("taubin"), [5, 10, 20, 50, 100, 200]),
    "MeshLab HC": (_meshlab("apply_coord_hc_laplacian_smoothing"), [1, 2, 3, 5, 8]),
    "MeshLab Laplacian": (
        _meshlab("apply_coord_laplacian_smoothing", cotangentweight=False),
        [1, 2, 3, 5, 8],
    ),
    "MeshLab Taubin": (_meshlab("apply_coord_taubin_smoothing"), [5, 10, 20, 50, 100, 200]),
    "MeshLab two-step": (_meshlab("apply_coord_two_steps_smoothing"), [1, 2, 3, 5, 8]),
    "trimesh Taubin": (_trimesh("taubin"), [5, 10, 20, 50, 100, 200, 500]),
    "trimesh Humphrey": (_trimesh("humphrey"), [2, 5, 10, 20, 50]),
}
#: the peers of ``--quick``: the best three on these scans in the full run
QUICK_PEERS = ("Open3D simple", "Open3D Laplacian", "MeshLab HC")


# ------------------------------------------------------------------------------------------------ ours


def ours(vertices, triangles):
    from o3d_lsmesh.fairing import constrained_fairing_arrays

    return constrained_fairing_arrays(vertices, triangles, None, method=None)  # = constrained_fairing(mesh)


COLUMNS = ["mean", "p90", "interior", "boundary", "signed", "angle", "degenerate"]


def run_scan(name, reference, sweep_lines):
    V, F = load_scan(name)
    boundary = boundary_vertices(F, len(V))
    raw = score(V, F, reference, boundary)
    peers = {}
    for label, (fn, sweep) in PEERS.items():
        entries = []
        for k in sweep:
            try:
                out, seconds = timed(lambda fn=fn, k=k: fn(V, F, k))
            except Exception as error:
                sweep_lines.append(f"{name} {label} {k}: failed ({error})")
                continue
            entries.append((k, score(out, F, reference, boundary), seconds))
        sweep_lines.append(f"{name} {label}: " + ", ".join(f"{k}: {s['mean']:.1f}" for k, s, _ in entries))
        peers[label] = min(entries, key=lambda e: e[1]["mean"])
    out, seconds = timed(lambda: ours(V, F))
    mine = score(out, F, reference, boundary)
    best_peer = min(peers.items(), key=lambda p: p[1][1]["mean"])
    return {
        "name": name,
        "n": len(V),
        "raw": raw,
        "peers": peers,
        "ours": mine,
        "ours_seconds": seconds,
        "ours_vertices": out,
        "best_peer": best_peer,
        "V": V,
        "F": F,
        "boundary": boundary,
    }


def multiresolution_rows(results, reference, levels=(1, 2, 3)):
    """Multiresolution fairing on each scan with the triangles of its non-manifold vertices removed."""
    from o3d_lsmesh.fairing import constrained_fairing_arrays, multiresolution_fairing
    from o3d_lsmesh.topology import nonmanifold_vertices

    rows = []
    for r in results:
        V, F = r["V"], r["F"]
        # removing a non-manifold vertex's triangles can pinch a neighbour: repeat until none is left
        Fk, Vk, removed = F, V, 0
        for _ in range(20):
            bad = nonmanifold_vertices(Fk, len(Vk))
            if len(bad) == 0:
                break
            keep = ~np.isin(Fk, bad).any(axis=1)
            removed += int(len(Fk) - keep.sum())
            used, Fk = np.unique(Fk[keep], return_inverse=True)
            Fk, Vk = Fk.reshape(-1, 3), Vk[used]
        boundary = boundary_vertices(Fk, len(Vk))
        row = [
            r["name"],
            removed,
            score(Vk, Fk, reference, boundary)["mean"],
            score(constrained_fairing_arrays(Vk, Fk, None, method=None), Fk, reference, boundary)["mean"],
        ]
        for level in levels:
            try:
                mesh = o3d.geometry.TriangleMesh(
                    o3d.utility.Vector3dVector(Vk), o3d.utility.Vector3iVector(Fk)
                )
                out = np.asarray(multiresolution_fairing(mesh, level).vertices)
                row.append(score(out, Fk, reference, boundary)["mean"])
            except ValueError as error:
                row.append(f"refused: {str(error)[:60]}")
        rows.append(row)
    return rows


#: where the time goes (2026-12-03, idle 2-core machine; the history below it from 2026-12-01 and -02)
SPEED_PROFILE = """\
Since 2026-12-03 the default solves meshes of 5k vertices and more by block conjugate gradients
preconditioned by the matrix's zero-fill incomplete Cholesky factor (IC(0), compiled,
``SPDSolver(preconditioner="ic0")``), started from the scan, each of its two solves stopped at 1e-4 of
its starting residual (``SPDSolver(reduction=)``, ``SCAN_REDUCTION``); below 5k, and with
``solver="cholmod"``, one sparse Cholesky factorization. The system's data term sits on every vertex,
so its condition number does not grow with the size: 6-11 iterations a solve from a few hundred
vertices to 1.4M. On the ten scans the result is within 5e-5 to 1.3e-4 mean edge lengths RMS (at most
6e-3 at a vertex) of the factor's, and every quality figure of realscans_denoise.md is the factor's
(mean distances within 0.001 um; degenerate rim triangles 213-374 against 216-380).

Earlier runs of this section on 2026-12-03 (medians of interleaved trials, wall / CPU ratio to
Open3D's Laplacian at its best count; the table above is a later run): 40k 3.55 / 4.23, 3.26 / 3.84,
3.39 / 4.03 and, in a slower hour (Open3D 0.068-0.083 s against 0.054-0.061 s), 3.99 / 5.01; 1.4M
2.69 / 2.57, 2.59 / 2.50, 2.76 / 2.63, 2.56 / 2.43. Our CPU time exceeds our wall time: the block
kernel's products and CG updates run on both cores from 20k rows, the triangular solves on one.

Whole calls, medians of 5-7, milliseconds (seconds at 1.4M), factor against IC(0)-CG:

| mesh | vertices | factor ms | IC(0)-CG ms | CG / factor | CG iterations, first solve |
|---|---|---|---|---|---|
| decimated bun000 | 752 | 7 | 6 | 0.84 | 3 |
| decimated bun000 | 3,597 | 31 | 17 | 0.57 | 3 |
| decimated bun000 | 6,893 | 57 | 33 | 0.58 | 3 |
| decimated bun000 | 13,149 | 120 | 61 | 0.51 | 3 |
| the ten scans | 30,144-39,977 | 254-449 | 137-196 | 0.41-0.54 | 7-11 |
| 300 defect soups (tests/defect_meshes.py), 500-vertex pieces | 150,300 | 478 | 564 | 1.18 | 7 |
| 10 scans merged, subdivided | 1,404,335 | 21.5 s | 8.0-8.1 s (AMG V-cycle: 12.3-12.8 s) | 0.37 | |

A soup of small pieces is the one case where the factor stays faster (its cost grows like each
component's size to the power 1.5); the rule that sent such soups to it (a component of 30k or more)
was dropped with the AMG path: 18% on an artificial soup against one more pass over the mesh on
every call.

Measured on the way (40k, bun000, one solve from the scan to 1e-3 of its start unless said):
Jacobi-preconditioned CG 36 iterations (0.17 s), symmetric Gauss-Seidel 15 (0.14 s), the AMG V-cycle
4 iterations but a 0.10 s set-up (0.22 s with pyamg's import), IC(0) 5-6 (0.06-0.07 s, set-up 0.02 s);
the triangular solves with the mirrored values (both passes read rows, sums in registers) 1.3-1.9 ms
against 4.0 ms for the scatter form of the backward pass. Stopping rule, ten scans, IC(0): 1e-2 of the
start moves the mean distance by up to 0.45 um, 3e-3 by 0.11, 1e-3 by 0.03, 1e-4 by 0.007 (the RMS
difference to the factor 2e-4 to 6e-4 mean edge lengths). At 1.4M the AMG V-cycle with the same
stopping rule took 12.3-12.8 s against IC(0)'s 8.0-8.1 s (Open3D 3.0-3.2 s in those runs). The block
kernel's loops run on both cores from 20k rows (was 100k): 40k 0.26 -> 0.22-0.24 s.

History. Until 2026-12-02 the default factored below 100k vertices (a component of 30k or more) and
ran CG with the AMG V-cycle to a relative residual of 1e-9 above. At 40k the factorization (0.76
GFlop after COLAMD on the 1-ring pattern, about 0.2 s on one core) and its analysis (0.05 s) were the
floor: 7.1-8.9x Open3D's five Laplacian iterations in wall time (6.2-7.5x CPU), and 4.5-5.2x at 1.4M
(21 V-cycles of ~0.2 s, AMG set-up 2.7 s). Measured then and not taken: METIS on the matrix (0.665
GFlop but a 0.26-0.30 s analysis), METIS or nested dissection of the 1-ring graph applied to the
2-ring matrix (6.3 and 5.7 GFlop), geometric nested dissection (1.15 GFlop; 72 s at 1.4M), the
quasi-definite mixed system [[mu H^T W H + lambda G, K^T], [K, -I]] (simplicial LDL^T 0.44 s against
0.23 s), one BLAS thread, CG preconditioned by the factor of the 1-ring part (0.40 against 0.33 s),
fewer candidate sweeps in the AMG set-up (no iteration change)."""


def speed_rows(results):
    """Interleaved timings: ours (defaults) against Open3D's Laplacian filter at its best count on that mesh."""
    rows = []
    big_v, big_f, offset = [], [], 0
    for r in results:
        big_v.append(r["V"])
        big_f.append(r["F"] + offset)
        offset += len(r["V"])
    merged = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(np.vstack(big_v)), o3d.utility.Vector3iVector(np.vstack(big_f))
    )
    merged = merged.subdivide_midpoint(number_of_iterations=1)
    counts = [r["peers"]["Open3D Laplacian"][0] for r in results]
    cases = [
        (results[0]["name"], results[0]["V"], results[0]["F"], counts[0]),
        (
            "10 scans merged, subdivided",
            np.asarray(merged.vertices).copy(),
            np.asarray(merged.triangles).astype(np.int64),
            int(np.median(counts)),
        ),
    ]
    for label, V, F, k in cases:
        mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(F))
        for trial in range(7 if len(V) < 200_000 else 3):
            wall_o3d, cpu_o3d = _wall_and_cpu(lambda: mesh.filter_smooth_laplacian(number_of_iterations=k))
            wall_ours, cpu_ours = _wall_and_cpu(lambda: ours(V, F))
            rows.append(
                [label, len(V), trial, k, wall_o3d, wall_ours, wall_ours / wall_o3d]
                + [cpu_o3d, cpu_ours, cpu_ours / cpu_o3d]
            )
    return rows


def _wall_and_cpu(fn) -> tuple[float, float]:
    """Wall and CPU (this process, every thread) seconds of one call."""
    wall, cpu = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - wall, time.process_time() - cpu


def speed_table(speed) -> str:
    """The interleaved timings as a table, with the median ratios (wall, and CPU time) per mesh."""
    header = ["mesh", "vertices", "trial", "o3d iterations", "o3d s", "ours s", "ratio"]
    header += ["o3d CPU s", "ours CPU s", "CPU ratio"]
    medians = "; ".join(
        f"{label} ({n} vertices) {np.median([r[6] for r in speed if r[0] == label]):.2f} wall, "
        f"{np.median([r[9] for r in speed if r[0] == label]):.2f} CPU"
        for label, n in dict.fromkeys((row[0], row[1]) for row in speed)
    )
    return markdown_table(header, speed) + f"\n\nTarget: ratio <= 5. Median ratio: {medians}."


def picture(result, reference, path):
    """Raw scan, Open3D's best and ours, coloured by distance to the reference (um), with a colour bar."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib import cm, colors

    from o3d_lsmesh.rendering import error_colors, render

    V, F = result["V"], result["F"]
    o3d_label = min(
        ((label, p) for label, p in result["peers"].items() if label.startswith("Open3D")),
        key=lambda lp: lp[1][1]["mean"],
    )
    label, (k, _, _) = o3d_label
    fn = PEERS[label][0]
    vmax_um = 250.0
    meshes = []
    for positions in (V, fn(V, F, k), result["ours_vertices"]):
        mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(positions), o3d.utility.Vector3iVector(F))
        distance_um = np.linalg.norm(positions - reference.closest(positions)[0], axis=1) * 1e6
        mesh.vertex_colors = o3d.utility.Vector3dVector(error_colors(distance_um, vmax_um))
        meshes.append(mesh)
    # look along the scanner's direction: the mean of the scan's area-weighted normals
    a, b, c = (V[F[:, i]] for i in range(3))
    view = np.cross(b - a, c - a).sum(axis=0)
    image = render(meshes, None, width=520, height=520, view_direction=view / np.linalg.norm(view))
    titles = [
        f"raw scan: {result['raw']['mean']:.0f} um",
        f"Open3D best ({label.split()[1]}, {k} it.): {o3d_label[1][1]['mean']:.0f} um",
        f"ours, defaults: {result['ours']['mean']:.0f} um",
    ]
    fig, ax = plt.subplots(figsize=(image.shape[1] / 100, image.shape[0] / 100 + 0.9), dpi=100)
    ax.imshow(image)
    ax.set_axis_off()
    w = image.shape[1] / 3
    for i, t in enumerate(titles):
        ax.text(w * (i + 0.5), -8, t, ha="center", va="bottom", fontsize=11)
    bar = fig.colorbar(
        cm.ScalarMappable(norm=colors.Normalize(0, vmax_um), cmap="viridis"),
        ax=ax,
        orientation="horizontal",
        fraction=0.05,
        pad=0.02,
    )
    bar.set_label(f"distance to the reference surface (um), {result['name']}")
    fig.savefig(path, bbox_inches="tight", dpi=100)
    plt.close(fig)


def main():
    import sys

    start = time.perf_counter()
    names = scan_names()
    if not names or not (DATA / REFERENCE).exists():
        print(f"skipping: no scans in {SCANS} (set O3D_LSMESH_SCANS) or no {REFERENCE} in {DATA}")
        return
    if "--speed-only" in sys.argv:
        # only the timing section: Open3D Laplacian's best count per scan from its own sweep, then the
        # interleaved timings (for re-measuring speed on a loaded machine without the 40-minute sweeps)
        reference = Reference()
        results = []
        for name in names:
            V, F = load_scan(name)
            boundary = boundary_vertices(F, len(V))
            fn, sweep = PEERS["Open3D Laplacian"]
            best = min(sweep, key=lambda k: score(fn(V, F, k), F, reference, boundary)["mean"])
            results.append({"name": name, "V": V, "F": F, "peers": {"Open3D Laplacian": (best, None, None)}})
        speed = speed_rows(results)
        write_markdown(
            "realscans_denoise_speed.md",
            "Denoising raw range scans: time of the default against Open3D's Laplacian at its best count",
            [
                ("Speed, interleaved", speed_table(speed)),
                ("Where the time goes", SPEED_PROFILE),
            ],
        )
        return
    quick = "--quick" in sys.argv
    if quick:
        # the peers that were best on these scans in the full run (Open3D simple first, then MeshLab HC and
        # Open3D Laplacian), with their sweeps: every target re-checked in minutes instead of 40 (the other
        # peers' best settings are in realscans_denoise.md and do not change)
        for label in list(PEERS):
            if label not in QUICK_PEERS:
                del PEERS[label]
    reference = Reference()
    sweep_lines: list[str] = []
    results = []
    for name in names:
        results.append(run_scan(name, reference, sweep_lines))
        r = results[-1]
        print(
            f"{name}: raw {r['raw']['mean']:.1f} um, best peer {r['best_peer'][0]} {r['best_peer'][1][1]['mean']:.1f}, "
            f"ours {r['ours']['mean']:.1f} ({r['ours_seconds']:.2f} s)",
            flush=True,
        )

    header = ["scan", "raw um"] + list(PEERS) + ["ours (defaults)", "ours / best peer"]
    table = []
    for r in results:
        best = r["best_peer"][1][1]["mean"]
        table.append(
            [r["name"].removesuffix(".ply"), r["raw"]["mean"]]
            + [f"{p[1]['mean']:.1f} ({p[0]})" for p in r["peers"].values()]
            + [r["ours"]["mean"], r["ours"]["mean"] / best]
        )
    detail_header = [
        "scan",
        "method",
        "setting",
        "mean um",
        "p90 um",
        "interior um",
        "boundary um",
        "signed um",
        "normal deg",
        "degenerate rim tris",
        "s",
        "/ best peer",
    ]
    detail = []
    for r in results:
        best = r["best_peer"][1][1]["mean"]
        detail.append(
            [r["name"].removesuffix(".ply"), "raw", "-"]
            + [r["raw"][c] for c in COLUMNS]
            + ["-", r["raw"]["mean"] / best]
        )
        for label, (k, s, seconds) in r["peers"].items():
            detail.append(
                [r["name"].removesuffix(".ply"), label, k]
                + [s[c] for c in COLUMNS]
                + [seconds, s["mean"] / best]
            )
        detail.append(
            [r["name"].removesuffix(".ply"), "ours", "defaults"]
            + [r["ours"][c] for c in COLUMNS]
            + [r["ours_seconds"], r["ours"]["mean"] / best]
        )

    ratios = np.array([r["ours"]["mean"] / r["best_peer"][1][1]["mean"] for r in results])
    # "best conventional filter" over the scans: the one peer whose best settings give the lowest mean error
    per_peer = {label: np.mean([r["peers"][label][1]["mean"] for r in results]) for label in PEERS}
    best_filter = min(per_peer, key=per_peer.get)
    ours_mean = float(np.mean([r["ours"]["mean"] for r in results]))
    best_each = float(np.mean([r["best_peer"][1][1]["mean"] for r in results]))
    shift_ours = np.array([r["raw"]["signed_interior"] - r["ours"]["signed_interior"] for r in results])
    shift_simple = np.array(
        [r["raw"]["signed_interior"] - r["peers"]["Open3D simple"][1]["signed_interior"] for r in results]
    )
    targets = [
        (
            f"- Beats every peer's best setting: {int((ratios < 1).sum())}/{len(ratios)} scans "
            f"(ours / best peer per scan: min {ratios.min():.3f}, mean {ratios.mean():.3f}, max {ratios.max():.3f})."
        ),
        (
            f"- Mean error over the scans: ours {ours_mean:.1f} um; best single conventional filter ({best_filter}, "
            f"best setting per scan) {per_peer[best_filter]:.1f} um: ratio {ours_mean / per_peer[best_filter]:.3f} "
            f"(target <= 0.97); against the best peer picked per scan {best_each:.1f} um: {ours_mean / best_each:.3f}."
        ),
        (
            f"- Interior inward shift (raw signed interior mean - result's, um): ours mean {shift_ours.mean():.1f} "
            f"(per scan {shift_ours.min():.1f} to {shift_ours.max():.1f}); Open3D simple at its best "
            f"{shift_simple.mean():.1f} ({shift_simple.min():.1f} to {shift_simple.max():.1f}); ours <= half of simple's on "
            f"{int((shift_ours <= shift_simple / 2).sum())}/{len(results)} scans."
        ),
    ]
    degenerate = {
        "raw": [r["raw"]["degenerate"] for r in results],
        "best peer": [r["best_peer"][1][1]["degenerate"] for r in results],
        "Open3D simple": [r["peers"]["Open3D simple"][1]["degenerate"] for r in results],
        "ours": [r["ours"]["degenerate"] for r in results],
    }
    targets.append(
        f"- Degenerate rim triangles (quality 4 sqrt(3) area / sum of squared edges < {DEGENERATE_QUALITY}, "
        "per scan, min-max): " + "; ".join(f"{k} {min(v)}-{max(v)}" for k, v in degenerate.items()) + "."
    )
    print("\n".join(targets), flush=True)
    if quick:
        write_markdown(
            "realscans_denoise_quick.md",
            "Denoising raw range scans, quick check: defaults against the best peers' best settings",
            [
                (
                    "Setup",
                    "`bench_realscans_denoise.py --quick`: as the full run (realscans_denoise.md) with the peers "
                    f"{', '.join(PEERS)} only (the best ones there); 'best peer' below is the best of these.",
                ),
                (
                    "Per scan: mean distance (um), each peer at its best setting (iterations)",
                    markdown_table(header, table),
                ),
                ("Targets", "\n".join(targets)),
                ("Per scan, every measure", markdown_table(detail_header, detail)),
            ],
        )
        print(f"total {time.perf_counter() - start:.0f} s", file=sys.stderr)
        return
    multires = multiresolution_rows(results, reference)
    print("multiresolution done", flush=True)
    speed = speed_rows(results)
    print("speed done", flush=True)
    sections = [
        (
            "Setup",
            (
                "Distances in micrometres from each scan vertex to the reference `bunny.ply` (Open3D "
                "RaycastingScene); 'signed' is along the reference normal at the closest point (outside "
                "positive); 'normal deg' is the mean angle between our vertex normals and the reference's. Peers "
                "run every setting of their sweep (iteration counts, listed below) and are shown at their best "
                "per scan; ours runs `constrained_fairing(mesh)` with no argument. Interior/boundary: vertices "
                "off/on an edge with one triangle. Times are wall seconds on a shared 2-core machine."
            ),
        ),
        (
            "Per scan: mean distance (um), each peer at its best setting (iterations)",
            markdown_table(header, table),
        ),
        ("Targets", "\n".join(targets)),
        ("Per scan, every measure", markdown_table(detail_header, detail)),
        (
            "Multiresolution fairing on the scans (non-manifold vertices' triangles removed; mean um)",
            markdown_table(
                ["scan", "triangles removed", "raw", "ours (defaults)"]
                + [f"multires level {lv}" for lv in (1, 2, 3)],
                multires,
            ),
        ),
        (
            "Speed: ours (defaults) vs Open3D filter_smooth_laplacian at its best count, interleaved",
            speed_table(speed),
        ),
        ("Sweeps (mean um)", "```\n" + "\n".join(sweep_lines) + "\n```"),
    ]
    write_markdown(
        "realscans_denoise.md", "Denoising raw range scans: defaults against every peer's best", sections
    )
    # the scan where ours gains most on the best peer
    picture_result = min(results, key=lambda r: r["ours"]["mean"] / r["best_peer"][1][1]["mean"])
    picture(picture_result, reference, REPO / "docs" / "images" / "07_realscan_denoise.png")
    print(f"total {time.perf_counter() - start:.0f} s", file=sys.stderr)


if __name__ == "__main__":
    main()
