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


#: where the time goes (per-step timings 2026-12-01 at load 5-8 on 2 cores; the iterative solves and the last run 2026-12-02)
SPEED_PROFILE = """\
Since 2026-12-02 the default solves meshes of 100k vertices and more by block
conjugate gradients through the solver gateway (its smoothed-aggregation AMG V-cycle, the 1-ring's
reverse Cuthill-McKee numbering, the first solve started from the scan) and factors below. Whole calls,
wall / CPU seconds, medians, idle machine:

| mesh | vertices | Open3D (5 its) | factor (CHOLMOD) | CG to 1e-9 | max difference / bbox |
|---|---|---|---|---|---|
| decimated bun000 | 2,954 | | 0.019 | 0.023 | |
| decimated bun000 | 11,099 | | 0.074 | 0.074 | |
| decimated bun000 | 21,276 | | 0.176 | 0.213 | |
| the ten scans, 30k-40k each | 30,144-39,977 | | 0.19-0.41 | 0.22-0.44 (CG / factor 0.78-1.36, median 1.03) | |
| bun000 | 39,977 | 0.021 / 0.026 | 0.298 / 0.469 | 0.258 / 0.355 | 6.2e-9 |
| 3 scans merged | 109,922 | 0.082 / 0.118 | 0.799 / 1.27 | 0.721 / 1.27 | 3.3e-8 |
| 10 scans merged | 359,556 | 0.281 / 0.390 | 2.81 / 4.19 | 2.30 / 3.80 | 5.9e-8 |
| 10 scans merged, subdivided | 1,404,335 | 2.70 / 3.51 | 16.7 / 25.6 | 9.53 / 14.1 | 6.6e-8 |
| 300 defect soups (tests/defect_meshes.py), 500-vertex pieces | 150,300 | | 0.49 | 1.22 | 7.3e-9 |

At 1.4M: 11 + 14 CG iterations (11 + 10 since 2026-12-03: the twicing solve stops at the absolute
residual the first reached, 1.0-1.3 s less, the result within 9.1e-8 of the bounding box of the
1e-9 solve's); structure and parameters 1.3 s, assembly 2.4 s (K^T K by the gateway's
compiled product on both cores: 0.3 s less than SciPy's), AMG levels 2.1 s, CG 6 s. Before the solver
work of issue #16 (renumbering, compiled products, work blocks kept per solve) CG was slower than the
factor at every size (the measurements at the end of this section). Below about 100k the two are level
and the factor, exact, is kept; so it is where no connected component reaches 30k vertices (the
factor's cost grows like each component's size to the power 1.5: a soup of small pieces factors fast).

Ours below 100k is one sparse Cholesky factorization of the 2-ring (bi-Laplacian pattern) normal matrix and two
back-substitutions; everything else is a few linear passes over the edges. CPU seconds per step (40k:
medians of 6-20 runs; 1.4M: one run each, interleaved), before and after the analysis from the 1-ring
pattern with COLAMD:

| step | before, 40k | after, 40k | before, 1.4M | after, 1.4M |
|---|---|---|---|---|
| validation + edge structure + parameters | 0.02 | 0.02 | 0.7 | 0.7 |
| assembly (K^T K + 1-ring terms, lower triangle) | 0.03-0.04 | 0.03-0.04 | 2.1-3.1 | 2.1-3.1 |
| analysis | 0.04-0.05 (AMD on the matrix) | 0.05-0.06 (COLAMD on the 1-ring) | 3.1 | 3.4 |
| factor flops | 0.90 GFlop | 0.76 GFlop | 51.4 GFlop | 46.5 GFlop |
| factorization, one BLAS thread | 0.21-0.23 | 0.19-0.21 | 15.1 | 13.7 |
| factorization, two threads (wall) | | | 31.0 | 19.8 |
| two solves | 0.04 | 0.04 | 1.5-2.1 | 1.5-2.1 |

CHOLMOD analyzes K^T K from the pattern of K (the 1-ring, 7 entries a row against the matrix's 18.5;
K^T K's pattern holds the whole matrix's) and factors the matrix with that analysis. Results equal to
round-off: max |new - old| at most 3.7e-15 of the bounding box on the ten scans, 3.9e-15 at 1.4M; the
quality figures below are unchanged. Interleaved whole runs on the loaded machine, 40k: CPU min 0.351 s
against 0.375 s (ten trials); the wall ratio moves more with the load than with the change (40k: 7.5 before,
5.7 in this run; 1.4M: 5.9 before, 3.6 in this run, where Open3D's OpenMP threads took 2.5x their CPU
time in wall time).

Measured and not taken (40k unless said): METIS on the matrix, 0.665 GFlop but a 0.26-0.30 s analysis
(1.4M: 35.2 GFlop, 15 s analysis); METIS or nested dissection of the 1-ring graph applied to the 2-ring
matrix, 6.3 and 5.7 GFlop (one-layer separators leave the halves coupled through 2-ring entries);
geometric nested dissection (coordinate bisection, two-layer separators, in numpy), 1.15 GFlop, and at
1.4M a 72 s factorization (the merged scans overlap in space); the quasi-definite mixed system
[[mu H^T W H + lambda G, K^T], [K, -I]] (1-ring blocks, 2n unknowns), 0.71 GFlop with AMD but only
CHOLMOD's simplicial LDL^T takes an indefinite matrix: 0.44 s against 0.23 s; the whole matrix as one
product [M^T, I] [M; Z] (no sum, no sort): 28 against 31 ms at 40k but 3.0 against 2.1 s at 1.4M (the
concatenations); one BLAS thread: 40k median wall 0.86 against 0.88 s (CPU 0.32 against 0.49, load 7),
1.4M factorization 29.5 against 19.8 s wall: the default thread count kept. Earlier (see git history):
CG preconditioned by the factor of the 1-ring part (0.40 against 0.33 s), simplicial factor (2-3x
slower). Measured 2026-12-02 (load 1-2), the system solved by block conjugate gradients started from
the scan, on ``_block_cg`` of the solver gateway: with a Jacobi preconditioner 57 + 94 iterations to a
relative residual of 1e-6 (0.76 s of CPU, max difference to the direct solve 2.0e-5 of the bounding
box); with the gateway's smoothed-aggregation AMG V-cycle 10 + 15 iterations (0.63 s against CHOLMOD's
0.69 s of CPU in the same process, 0.63 s against 0.43 s wall; max difference 2.0e-5), at 1.4M 12 + 20
iterations, 24.7 s against 27.7 s of CPU but 30.7 s against 20.5 s wall: no faster than the
factorization, and 1e-7 costs 25% more. At 40k the floor is the factorization (0.76 GFlop, about
0.2 s on one core) and its analysis (0.05 s), while Open3D's 5 Laplacian iterations take 0.03-0.06 s
of wall time at load 1-2 (its OpenMP threads use both cores). The run before CG took over, at load 1-2:
40k wall ratio 5.2-15.6 (median 7.9), CPU ratio 4.6-14.3 (median 7.1); 1.4M wall
4.7-7.4 (median 5.2), CPU 5.3-7.5 (median 5.5). The earlier runs on the loaded machine (load 5-8) gave
5.7 and 3.6 in wall time, because there Open3D's wall time was 2.5x its CPU time and ours 1.5-1.7x:
the lightly loaded machine is the fair measure, and the target (5x) was not met at either size
then. With CG from 100k vertices the 1.4M ratio depends on the machine more than on the code:
3.2-3.7 in the first runs (load 1-2), 5.29 and 5.27 on an idle machine on 2026-12-02, and on
2026-12-03 (another machine, Open3D 2.0-3.2 s there against 1.6-2.0 s) 5.04 before the twicing
solve's absolute stop and 4.51, 5.16 and 4.95 after in three runs (CPU 5.9 before; 5.3, 5.9 and 5.7
after; the last is the table at the top): at the 5x line, not clearly under it; not met at 40k
(7.1-8.9 wall, 6.2-7.5 CPU)."""


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
