"""Raw scans benchmark: every public operation with its defaults on real range scans, beside Open3D and fast-simplification.

For each raw scan in ``O3D_LSMESH_SCANS`` (default ``../shared/data/scans``) and
``bunny_scan.ply`` (``O3D_LSMESH_DATA``), in one process:

* ``timing``: wall time of every public operation with its default options (an
  operation that refuses the scan is reported with the start of its message), next
  to Open3D's ``filter_smooth_simple``, ``filter_smooth_laplacian`` and
  ``filter_smooth_taubin`` and fast-simplification's ``simplify`` (defaults, 50%);
  ratios are to Open3D's Taubin filter measured in the same run. Operations that
  need a size get one: ``count`` = one per component plus 0.1% of the vertices,
  ``ls_mesh`` controls = one per component plus 1% random, 1% unknown
  vertices for ``reconstruct_geometry``; ``spectral_approximation`` (``k=20``) runs
  on ``bunny_scan`` only (tens of seconds per scan, see the note in the output).
* ``topology``: the counts of :func:`o3d_lsmesh.topology_summary` before and after
  the operations that change or keep the connectivity.
* ``pinches``: the measurement behind "pinch vertices move" in
  :mod:`o3d_lsmesh.fairing.boundary_curve`: distance of the boundary vertices to the
  reference surface ``bunny.ply`` after ``constrained_fairing`` with the pinches
  moving (default) or held (the boundary cut into chains at the pinches).

Denoising quality against the peers is ``benchmarks/bench_realscans_denoise.py``'s
(``results/realscans_denoise.md``).

Run: ``.venv/bin/python benchmarks/bench_realscans.py [section ...]`` (all sections
by default; a few minutes on 2 cores). Writes ``benchmarks/results/realscans.md``.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np
import open3d as o3d
from _common import DATA, REPO, markdown_table, timed, write_markdown

import o3d_lsmesh
from o3d_lsmesh.core.boundary import boundary_chains, boundary_halfedges
from o3d_lsmesh.core.connectivity import Connectivity
from o3d_lsmesh.lsmesh.selection import start_vertices

SCANS = Path(os.environ.get("O3D_LSMESH_SCANS", REPO.parent / "shared" / "data" / "scans"))
SECTIONS = ("timing", "topology", "pinches")


def scan_list() -> list[tuple[str, Path]]:
    """(name, path) of every raw scan, then bunny_scan.ply; absent files are skipped with a message."""
    scans = [(p.stem, p) for p in sorted(SCANS.glob("*.ply"))] if SCANS.is_dir() else []
    if not scans:
        print(f"no raw scans in {SCANS} (set O3D_LSMESH_SCANS)")
    if (DATA / "bunny_scan.ply").exists():
        scans.append(("bunny_scan", DATA / "bunny_scan.ply"))
    else:
        print(f"bunny_scan.ply not found in {DATA} (set O3D_LSMESH_DATA)")
    return scans


def _read(path: Path):
    mesh = o3d.io.read_triangle_mesh(str(path))
    return mesh, np.asarray(mesh.vertices).copy(), np.asarray(mesh.triangles).astype(np.int64)


REFUSALS: dict = {}


def _attempt(op, fn):
    """(result, seconds) or (None, 'refused'), the first message of each refused operation kept for the notes."""
    try:
        result, seconds = timed(fn)
    except (ValueError, MemoryError) as error:
        REFUSALS.setdefault(op, str(error))
        return None, "refused"
    return result, seconds


def _operations(name, mesh, V, F):
    """Every public operation with its defaults (and sizes where one is required)."""
    import fast_simplification

    n = len(V)
    components, _ = Connectivity(F, n).components
    rng = np.random.default_rng(0)
    count = components + n // 1000
    controls = np.union1d(start_vertices(V, F), rng.choice(n, n // 100, replace=False))
    unknown = rng.choice(n, n // 100, replace=False)
    state = {}

    def encode():
        state["data"] = o3d_lsmesh.encode_geometry(mesh, count)
        return state["data"]

    ops = {
        "topology_summary": lambda: o3d_lsmesh.topology_summary(mesh),
        "fairing (default)": lambda: o3d_lsmesh.constrained_fairing(mesh),
        "fairing local": lambda: o3d_lsmesh.constrained_fairing(mesh, method="local"),
        "fairing global": lambda: o3d_lsmesh.constrained_fairing(mesh, method="global"),
        "fill_holes": lambda: o3d_lsmesh.fill_holes(mesh),
        "boundary curves": lambda: o3d_lsmesh.smooth_boundary_curves(mesh),
        "build_hierarchy": lambda: o3d_lsmesh.build_hierarchy(mesh),
        "multires. fairing": lambda: o3d_lsmesh.multiresolution_fairing(mesh, 1),
        "from_fast_simpl.": lambda: o3d_lsmesh.from_fast_simplification(mesh),
        "ls_mesh": lambda: o3d_lsmesh.ls_mesh(mesh, controls),
        "reconstruct": lambda: o3d_lsmesh.reconstruct_geometry(mesh, unknown),
        "select": lambda: o3d_lsmesh.select_control_points(mesh, count),
        "approximate": lambda: o3d_lsmesh.approximate(mesh, count),
        "encode": encode,
        "decode": lambda: o3d_lsmesh.decode_geometry(mesh, state["data"]),
        "o3d simple": lambda: mesh.filter_smooth_simple(),
        "o3d laplacian": lambda: mesh.filter_smooth_laplacian(),
        "o3d taubin": lambda: mesh.filter_smooth_taubin(),
        "fast_simplification": lambda: fast_simplification.simplify(V, F, 0.5),
    }
    if name == "bunny_scan":
        ops["spectral k=20"] = lambda: o3d_lsmesh.spectral_approximation(mesh, 20)
    return ops, count


TOPOLOGY_KEYS = (
    "components",
    "surface_pieces",
    "boundary_loops",
    "boundary_components",
    "nonmanifold_vertices",
    "nonmanifold_edges",
    "degenerate_triangles",
    "total_genus",
)


def _counts(summary: dict) -> list:
    holes = "/".join(str(v) for v in summary["holes_by_size"].values())
    return [summary["vertices"], summary["triangles"], *(summary[k] for k in TOPOLOGY_KEYS), holes]


def timing_and_topology(scans, *, want_timing=True, want_topology=True):
    timing_rows, topology_rows, notes = [], [], []
    names = None
    for name, path in scans:
        mesh, V, F = _read(path)
        ops, count = _operations(name, mesh, V, F)
        results, times = {}, {}
        for op, fn in ops.items():
            results[op], times[op] = _attempt(op, fn)
            print(
                f"{name:12s} {op:20s} {times[op] if isinstance(times[op], str) else f'{times[op]:.3f} s'}",
                flush=True,
            )
        assert np.array_equal(np.asarray(mesh.vertices), V), "an operation modified its input"
        if names is None:
            names = list(ops)
        taubin = times["o3d taubin"]
        timing_rows.append(
            [name, len(V), count]
            + [
                times[op]
                if isinstance(times.get(op), (str, type(None)))
                else f"{times[op]:.3f} ({times[op] / taubin:.0f}x)"
                for op in names
            ]
        )
        if name == "bunny_scan" and "spectral k=20" in times:
            notes.append(
                f"spectral_approximation(k=20) on bunny_scan: {times['spectral k=20']}"
                if isinstance(times["spectral k=20"], str)
                else f"spectral_approximation(k=20) on bunny_scan: {times['spectral k=20']:.1f} s"
            )
        if want_topology:
            before = _counts(o3d_lsmesh.topology_summary(mesh))
            same, changed = [], []
            for op in (
                "fairing (default)",
                "fairing local",
                "fairing global",
                "boundary curves",
                "o3d taubin",
            ):
                if results.get(op) is not None:
                    after = _counts(o3d_lsmesh.topology_summary(results[op]))
                    (same if after == before else changed).append((op, after))
            if results.get("fill_holes") is not None:
                changed.append(("fill_holes", _counts(o3d_lsmesh.topology_summary(results["fill_holes"]))))
            simplified = results.get("fast_simplification")
            if simplified is not None:
                changed.append(
                    (
                        "fast_simplification 50%",
                        _counts(
                            o3d_lsmesh.topology_summary(
                                (
                                    np.asarray(simplified[0], dtype=np.float64),
                                    np.asarray(simplified[1], dtype=np.int64),
                                )
                            )
                        ),
                    )
                )
            for op in ("build_hierarchy", "from_fast_simpl."):
                hierarchy = results.get(op)
                if hierarchy is not None and len(hierarchy) > 1:
                    top = len(hierarchy) - 1
                    changed.append(
                        (
                            f"{op} level {top}",
                            _counts(o3d_lsmesh.topology_summary(hierarchy.level_arrays(top))),
                        )
                    )
            label = "input" + (f" (= {', '.join(op for op, _ in same)})" if same else "")
            topology_rows.append([name, label, *before])
            topology_rows += [[name, op, *after] for op, after in changed]
    sections = []
    if want_timing and names:
        # ops with a time on every scan go first; the table is split in two to stay readable
        half = len(names) // 2 + 1
        for part in (names[:half], names[half:]):
            columns = [names.index(op) for op in part]
            sections.append(
                (
                    "Time of every operation with defaults, s (ratio to Open3D's filter_smooth_taubin)",
                    markdown_table(
                        ["scan", "V", "count"] + part,
                        [row[:3] + [row[3 + c] for c in columns] for row in timing_rows],
                    ),
                )
            )
        notes += [f"{op} refused the scans: {message}" for op, message in REFUSALS.items()]
        if notes:
            sections.append(("Notes", "\n".join(f"- {note}" for note in notes)))
    if want_topology and topology_rows:
        sections.append(
            (
                "topology_summary before and after (holes = loops with 3 / 4-9 / 10-99 / 100-999 / 1000+ edges)",
                markdown_table(["scan", "mesh", "V", "F", *TOPOLOGY_KEYS, "holes"], topology_rows),
            )
        )
    return sections


def pinches(scans):
    """Distance of boundary vertices to bunny.ply after constrained_fairing, pinches moving or held."""
    from o3d_lsmesh.fairing import constrained

    reference = DATA / "bunny.ply"
    if not reference.exists():
        return [("Pinch vertices", f"bunny.ply not found in {DATA}")]
    ref = o3d.t.geometry.TriangleMesh.from_legacy(o3d.io.read_triangle_mesh(str(reference)))
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(ref)

    def distance(points):
        return scene.compute_distance(o3d.core.Tensor(points.astype(np.float32))).numpy().astype(np.float64)

    # the fairing walks its boundary curves with core.boundary.boundary_curves (loops pass through the
    # pinches, which move); held: the boundary cut into chains at the pinches, whose ends are held
    moving = constrained.boundary_curves

    def held(triangles, n, **_edges):
        return boundary_chains(triangles, n)

    rows, totals = [], []
    for name, path in scans:
        if name == "bunny_scan":
            continue  # the same scan as bun000
        _, V, F = _read(path)
        n = len(V)
        chains = boundary_chains(F, n)
        pinch = chains.junctions
        boundary = np.unique(boundary_halfedges(F, n))
        ends = [c[[1, -2]] for c in chains.chains]
        near = np.setdiff1d(np.unique(np.concatenate(ends)) if ends else np.zeros(0, dtype=np.int64), pinch)
        line = []
        variants = [("input", None, None)] + [
            (f"{m}, pinches {h}", m, h) for m in ("local", "global") for h in ("move", "held")
        ]
        for _label, method, mode in variants:
            if method is None:
                P = V
            else:
                constrained.boundary_curves = moving if mode == "move" else held
                try:
                    P = o3d_lsmesh.fairing.constrained_fairing_arrays(V, F, method=method)
                finally:
                    constrained.boundary_curves = moving
            line += [
                1e6 * distance(P[pinch]).mean(),
                1e6 * distance(P[near]).mean(),
                1e6 * distance(P[boundary]).mean(),
            ]
        totals.append(line)
        rows.append([name, len(pinch)] + [f"{x:.1f}" for x in line])
        print(name, " ".join(rows[-1][2:]), flush=True)
    if not rows:
        return []
    mean = np.mean(totals, axis=0)
    rows.append(["mean", sum(r[1] for r in rows)] + [f"{x:.1f}" for x in mean])
    header = ["scan", "pinches"]
    for label in ("input", "local move", "local held", "global move", "global held"):
        header += [f"{label}: pinch", "chain nbrs", "boundary"]
    return [
        (
            "Pinch vertices: mean distance to bunny.ply (um) of pinch vertices, their chain neighbours and all "
            "boundary vertices, after constrained_fairing with defaults",
            markdown_table(header, rows),
        )
    ]


def main(sections=SECTIONS) -> Path:
    unknown = [s for s in sections if s not in SECTIONS]
    if unknown:
        raise SystemExit(f"sections must be among {SECTIONS}, got {unknown}")
    scans = scan_list()
    start = time.perf_counter()
    out = []
    if "timing" in sections or "topology" in sections:
        out += timing_and_topology(
            scans, want_timing="timing" in sections, want_topology="topology" in sections
        )
    if "pinches" in sections:
        out += pinches(scans)
    out.append(
        (
            "Run",
            f"{len(scans)} meshes, {time.perf_counter() - start:.0f} s, open3d {o3d.__version__}, "
            f"o3d_lsmesh {o3d_lsmesh.__version__}",
        )
    )
    return write_markdown("realscans.md", "Raw scans: every operation with defaults", out)


if __name__ == "__main__":
    main(tuple(sys.argv[1:]) or SECTIONS)
