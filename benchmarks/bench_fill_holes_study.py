"""Hole filling on every closed mesh: ours against CGAL and MeshLib, per mesh, with leave-one-mesh-out choices.

The tuned benchmark (``bench_fill_holes.py``) was built on the horse and the camel. This study asks
whether its choices hold on meshes they were not made on: every closed, edge-manifold mesh of the data
folder (``$O3D_LSMESH_DATA``), geodesic disks of 2.5h, 6h and 15h (h: the mean edge length) cut around
``HOLES`` seeded centres each (a centre is re-drawn until the cut leaves one hole), and every hole filled
by

* ours: :func:`o3d_lsmesh.holes.fill_holes_arrays` with its defaults, and each candidate setting
  of the leave-one-mesh-out table (continuity 1 / 2, cotangent / uniform weights, density 0.7 / 1 / 1.4);
* CGAL ``triangulate_refine_and_fair_hole``, continuity 1 and 2 (density sqrt(2), CGAL's default);
* MeshLib ``fillHoleNicely`` (its defaults).

Measured per hole: mean and two-sided Hausdorff distance of the fill to the removed true surface (in h),
the smallest angle of the new triangles, closed (no boundary edge left), edge- and vertex-manifold,
consistently oriented, intersecting triangle pairs that involve a new triangle, and wall time per hole.
Reported per mesh and size, never only pooled, with the paired-bootstrap 95% interval of the ratio of
means ours / CGAL continuity 2.

Leave one mesh out: each candidate setting is scored on every mesh but one (the mean over those meshes'
sizes of the ratio of means against CGAL continuity 2), the best is kept, and its ratio on the mesh left
out is printed beside the default's. A default that needs the left-out mesh to look good is fitted.

Run: ``.venv/bin/python benchmarks/bench_fill_holes_study.py [--holes N] [--meshes a.ply,b.ply]``
(peers: ``pip install -r benchmarks/requirements.txt``; a missing peer is skipped). Writes
``benchmarks/results/fill_holes_study.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # see bench_fill_holes.py

import numpy as np
from _common import DATA, load_mesh, markdown_table, write_markdown
from bench_fill_holes import (
    available,
    boundary_edges,
    boundary_loop_count,
    cgal,
    cut_disk,
    mean_edge,
    measure,
    meshlib,
    ratio_interval,
)

from o3d_lsmesh.holes import HoleFiller

RADII = (2.5, 6.0, 15.0)
HOLES = 10
SEED = 37  # fixed before any result of this study was seen
TIMED = 3  # fills timed per tool and hole, the best kept
#: the leave-one-mesh-out candidates: (label, fill_holes_arrays options); the first is the default
CANDIDATES = [
    ("default", {}),
    ("continuity 1", {"continuity": 1}),
    ("uniform weights", {"weights": "uniform"}),
    ("density 0.7", {"density": 0.7}),
    ("density 1.4", {"density": 1.4}),
]


NOTES = """\
* The run: 2026-12-04 21:10 UTC, the fill of commit 202b2cf (before the Delaunay-restricted programme of
  the next point): the column "ours" is Liepa's programme over every triangle. igea (134k vertices,
  closed) was left out for time (about a minute per hole for the nine fills and their measures).
* Where ours loses to CGAL continuity 2 (ratio of means above 1): eight 6h (1.64, interval 1.40-1.90),
  octopus 6h (1.53, 1.26-1.79), screwdriver 2.5h (1.27, 1.12-1.38), octopus 2.5h (1.17), screwdriver 15h
  (1.24), camel 15h (1.06), horse 15h (1.04), feline 6h (1.03); the intervals of the last five hold 1.
  Why, each part of ours swapped on the same holes (scratch runs):
  - the triangulation: on eight 6h (a hole across the tube) CGAL's own triangulation of each loop
    (``triangulate_hole_polyline``, the mesh's third points), refined and faired by ours: 1.635 -> 1.173;
    Liepa's programme over the triangles of the loop points' 3D Delaunay tetrahedralization (CGAL's
    default search space, Zou et al. 2013): 1.123. Unrestricted, the programme's smallest largest
    dihedral angle takes triangles spanning the tube, and fairing keeps the shape they give. Adopted
    (commit 242a3ff); the same holes, ours with and without it (holes ours left open left out, so
    eight's score is not the table's above):

    | mesh | size | holes | default / CGAL c2 | Delaunay-restricted / CGAL c2 | holes Delaunay closer than default |
    |---|---|---|---|---|---|
    | camel | 2.5h | 10 | 0.833 | 0.765 | 5 (same 1) |
    | camel | 6h | 10 | 0.849 | 0.978 | 4 (same 0) |
    | camel | 15h | 10 | 1.062 | 1.061 | 4 (same 1) |
    | eight | 2.5h | 10 | 0.894 | 0.719 | 5 (same 1) |
    | eight | 6h | 10 | 1.635 | 1.123 | 9 (same 0) |
    | eight | 15h | 10 | 0.981 | 0.972 | 4 (same 0) |
    | feline | 2.5h | 10 | 0.896 | 0.838 | 6 (same 1) |
    | feline | 6h | 10 | 1.029 | 1.052 | 4 (same 0) |
    | feline | 15h | 10 | 0.970 | 0.914 | 7 (same 0) |
    | horse | 2.5h | 10 | 0.855 | 0.806 | 4 (same 4) |
    | horse | 6h | 10 | 0.824 | 0.759 | 5 (same 0) |
    | horse | 15h | 10 | 1.042 | 1.023 | 5 (same 0) |
    | octopus | 2.5h | 10 | 1.174 | 1.257 | 3 (same 0) |
    | octopus | 6h | 10 | 1.528 | 1.446 | 3 (same 2) |
    | octopus | 15h | 10 | 0.917 | 0.901 | 6 (same 3) |
    | screwdriver | 2.5h | 10 | 1.267 | 1.209 | 6 (same 1) |
    | screwdriver | 6h | 10 | 0.742 | 0.759 | 6 (same 0) |
    | screwdriver | 15h | 10 | 1.237 | 1.229 | 6 (same 0) |
    | venus_head | 2.5h | 10 | 0.929 | 0.900 | 5 (same 3) |
    | venus_head | 6h | 10 | 0.955 | 0.889 | 5 (same 0) |
    | venus_head | 15h | 10 | 0.793 | 0.781 | 5 (same 0) |

    | left out | chosen on the others (default or Delaunay) | its score | default | Delaunay |
    |---|---|---|---|---|
    | camel | delaunay | 0.935 | 0.915 | 0.935 |
    | eight | delaunay | 0.938 | 1.170 | 0.938 |
    | feline | delaunay | 0.935 | 0.965 | 0.935 |
    | horse | delaunay | 0.863 | 0.907 | 0.863 |
    | octopus | delaunay | 1.201 | 1.206 | 1.201 |
    | screwdriver | delaunay | 1.066 | 1.082 | 1.066 |
    | venus_head | delaunay | 0.857 | 0.892 | 0.857 |

  - the fairing system: ``L^(k+1) x = 0`` at the new vertices (Liepa's and CGAL's) instead of the
    least-squares energy, ours' weights: camel 2.5h 0.833 -> 0.892, eight 6h 1.635 -> 1.604. With the
    Delaunay programme and cotangent weights read off the refined, unfaired patch (CGAL's whole
    pipeline): eight 6h 1.123 -> 0.980 and octopus 6h 1.446 -> 1.028 (holes across thin parts), but
    camel 2.5h 0.765 -> 0.987, octopus 2.5h 1.257 -> 1.380, screwdriver 6h 0.759 -> 0.816, camel 15h
    1.061 -> 1.055: not adopted (better on one kind of hole, worse on another; no rule found here
    that tells them apart without the truth).
  - the tangential relaxation after fairing: no effect (camel 2.5h 0.833, 0.837 without).
  - continuity 1, uniform weights, density 0.7 and 1.4: the leave-one-mesh-out table above; the
    default is chosen on four of seven folds, density 1.4 on three, where it is worse on the mesh left
    out (horse 1.008 against 0.907, screwdriver 1.237 against 1.082, venus_head 1.054 against 0.892):
    the default stays.
* Left open (every one named in the warning and ``FillReport``): eight 15h, one cut drawn twice (27
  edges; the 15h disk takes most of the eight, the rest is a small open piece): taken as the outer
  border, closed by ``fill_border=True`` (continuity 2); octopus 2.5h #3 and 6h #7: every fill crosses
  the surface (the octopus crosses itself where tentacles touch; CGAL's fills there cross with 61 and
  10 pairs). Every fill ours made is closed, manifold, oriented and free of crossings; CGAL's cross on
  9 holes (octopus 7, camel 1, feline 1).
* Smallest angle at least CGAL's: 146 of the 206 holes both closed (71%; at least 80% on 8 of the 21
  mesh-size cells; lowest eight 6h 3/10, feline 15h 4/10).
* Time (CPU, prebuilt structures): within 2x of CGAL on 17 of 21 cells (0.8-1.9x); above on feline
  2.5h (2.2x), octopus 2.5h (2.3x), octopus 15h (2.1x: 15h disks on tentacle tips leave short loops)
  and venus_head 2.5h (2.3x), each under 3 ms a hole against CGAL's 1-1.4 ms.
"""


def closed_meshes(names):
    """(name, V, T) of every closed, edge-manifold mesh asked for (duplicates merged, unreferenced dropped)."""
    for name in names:
        mesh = load_mesh(name)
        if mesh is None:
            continue
        mesh.remove_duplicated_vertices()
        mesh.remove_unreferenced_vertices()
        V, T = np.asarray(mesh.vertices), np.asarray(mesh.triangles).astype(np.int64)
        if boundary_loop_count(V, T) or not mesh.is_edge_manifold():
            continue
        yield name[:-4], V, T


def simple_cut(V, T, radius, rng):
    """:func:`cut_disk`, re-drawn until the hole's loop is simple: a loop through a vertex twice leaves a
    vertex no fill can make manifold (CGAL's ``Polyhedron_3`` does not read such a mesh)."""
    for _ in range(20):
        holed, removed = cut_disk(V, T, radius, rng)
        if boundary_edges(*holed) == len(np.unique(boundary_vertices(*holed))):
            return holed, removed
    raise RuntimeError("no centre gives a single simple hole")


def boundary_vertices(V, T):
    e = np.sort(np.concatenate([T[:, [0, 1]], T[:, [1, 2]], T[:, [2, 0]]]), axis=1)
    keys, count = np.unique(e[:, 0] * len(V) + e[:, 1], return_counts=True)
    b = keys[count == 1]
    return np.concatenate([b // len(V), b % len(V)])


def ours_with(options):
    """Timed as CGAL is: the whole-mesh analysis (``HoleFiller``, as CGAL's ``Polyhedron_3``) built before
    the clock; CPU time of the process (both single-threaded), which the other jobs of a shared machine
    do not inflate as they do the wall clock; the best of ``TIMED`` fills (the first of a run also pays
    the imports of the fill's modules)."""

    def run(V, T):
        filler, best = HoleFiller(V, T), np.inf
        for _ in range(TIMED):
            start = time.process_time()
            out = filler.fill(**options)
            best = min(best, time.process_time() - start)
        return (out.vertices, out.triangles), best

    return run


def cgal_once(continuity, repeat=1):
    """CGAL's fill, the best of ``repeat`` (each on a fresh ``Polyhedron_3``, built before the clock)."""
    run = cgal(continuity)

    def once(V, T):
        out, clock = run(V, T, repeat=repeat)
        return out, clock.cpu

    return once


def run_study(meshes_asked, count, save=None):
    """Every tool on ``count`` seeded holes per closed mesh and size: ({(mesh, radius): [row per hole]},
    the meshes). With ``save``, the rows are written there after each hole, and the holes a former run
    wrote there are read back instead of filled again (the same seeded cuts are still drawn)."""
    names = meshes_asked.split(",") if meshes_asked else sorted(p.name for p in DATA.glob("*.ply"))
    tools = [(label, ours_with(options)) for label, options in CANDIDATES]
    peers = []
    if available("CGAL"):
        peers += [("CGAL c2", cgal_once(2, TIMED)), ("CGAL c1", cgal_once(1, TIMED))]
    if available("meshlib"):
        peers.append(("MeshLib", meshlib))
    rng = np.random.default_rng(SEED)
    rows: dict[tuple[str, float], list[dict]] = {}
    done = {}
    if save and os.path.exists(save):
        with open(save) as f:
            done = {(n, float(r)): c for n, r, c in json.load(f)["rows"]}
    meshes = []
    for name, V, T in closed_meshes(names):
        meshes.append(name)
        h = mean_edge(V, T)
        for radius in RADII:
            for k in range(count):
                try:
                    holed, (_, removed) = simple_cut(V, T, radius * h, rng)
                except RuntimeError:
                    print(f"{name} {radius:g}h: no centre leaves a single simple hole")
                    break
                if k < len(done.get((name, radius), [])):
                    rows.setdefault((name, radius), []).append(done[(name, radius)][k])
                    continue
                case = {"holed": holed, "h": h, "truth": {"full": (V, T), "removed": removed}}
                row = {}
                for label, tool in tools + peers:
                    out, seconds = tool(*holed)
                    row[label] = measure(case, out, seconds, 1)
                rows.setdefault((name, radius), []).append(row)
                if save:
                    with open(save, "w") as f:
                        json.dump({"holes": count, "rows": [[n, r, c] for (n, r), c in rows.items()]}, f)
                print(
                    name,
                    f"{radius:g}h",
                    k,
                    " ".join(f"{t}={row[t]['mean dist (h)']:.4g}" for t in row),
                    flush=True,
                )
    return rows, meshes


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--holes", type=int, default=HOLES, help="seeded holes per mesh and size")
    parser.add_argument(
        "--meshes", help="comma-separated file names (default: every closed mesh in the data folder)"
    )
    parser.add_argument(
        "--save", help="write every hole's measures to this JSON file as they come (a rerun resumes from it)"
    )
    parser.add_argument("--load", help="tabulate the measures of a --save file instead of running")
    parser.add_argument(
        "--out", default="fill_holes_study.md", help="the results file (a --holes subset: another)"
    )
    args = parser.parse_args()
    if args.load:
        with open(args.load) as f:
            saved = json.load(f)
        holes = saved["holes"]
        rows = {(name, float(radius)): cell for name, radius, cell in saved["rows"]}
        meshes = list(dict.fromkeys(name for name, _ in rows))
    else:
        holes, rows, _ = args.holes, *run_study(args.meshes, args.holes, args.save)
        meshes = list(dict.fromkeys(name for name, _ in rows))
    if not meshes:
        print(f"no closed mesh found in {DATA}")
        return 0
    reference = "CGAL c2" if "CGAL c2" in next(iter(rows.values()))[0] else None

    def filled(row):  # a fill that left the hole open has no distance: it counts apart, as a failure
        return np.isfinite(row["mean dist (h)"]) and row["boundary edges"] == 0

    def both(cell, label):  # the holes that ``label`` and the reference both closed
        return [r for r in cell if filled(r[label]) and (reference is None or filled(r[reference]))]

    def mean_of(cell, label, key="mean dist (h)"):
        values = [r[label][key] for r in cell if filled(r[label])]
        return float(np.mean(values)) if values else float("nan")

    header = [
        "mesh",
        "size",
        "holes",
        "closed: ours / CGAL c2",
        "ours",
        "CGAL c2",
        "CGAL c1",
        "MeshLib",
        "ours / CGAL c2",
        "95% interval",
    ]
    header += [
        "Hausdorff ours / CGAL c2",
        "min angle >= CGAL c2",
        "ours: closed, manifold, oriented",
        "ours crossing fills",
    ]
    header += ["CGAL c2 crossing fills", "time/hole ours / CGAL c2 (ms)"]
    table = []
    for (name, radius), cell in rows.items():
        closed = f"{sum(filled(r['default']) for r in cell)} / " + (
            str(sum(filled(r[reference]) for r in cell)) if reference else "-"
        )
        line = [name, f"{radius:g}h", len(cell), closed, mean_of(cell, "default")]
        line += [mean_of(cell, p) if p in cell[0] else "-" for p in ("CGAL c2", "CGAL c1", "MeshLib")]
        if reference:
            pairs = both(cell, "default")
            a = np.array([r["default"]["mean dist (h)"] for r in pairs])
            b = np.array([r[reference]["mean dist (h)"] for r in pairs])
            angles = sum(r["default"]["min angle (deg)"] >= r[reference]["min angle (deg)"] for r in pairs)
            line += [float(a.mean() / b.mean()) if len(a) else "-", ratio_interval(a, b)]
            line += [
                f"{mean_of(cell, 'default', 'Hausdorff (h)'):.3g} / {mean_of(cell, reference, 'Hausdorff (h)'):.3g}"
            ]
            line += [f"{angles} / {len(pairs)}"]
        else:
            line += ["-", "-", "-", "-"]
        valid = sum(
            r["default"]["boundary edges"] == 0
            and r["default"]["manifold"] == "yes"
            and r["default"]["oriented"] == "yes"
            for r in cell
        )
        line += [f"{valid} / {len(cell)}", sum(r["default"]["self-int. pairs"] > 0 for r in cell)]
        line += [sum(r[reference]["self-int. pairs"] > 0 for r in cell) if reference else "-"]
        line += [
            f"{mean_of(cell, 'default', 'time/hole (ms)'):.3g} / {mean_of(cell, reference, 'time/hole (ms)'):.3g}"
            if reference
            else "-"
        ]
        table.append(line)
    sections = [
        ("Per mesh and size (mean distance to the removed surface, in h)", markdown_table(header, table))
    ]
    if reference:
        # each candidate's score on a mesh: the mean over its sizes of the ratio of means against CGAL c2
        def score(label, mesh):
            """Mean over the mesh's sizes of the ratio of means on the holes both closed; a hole the setting
            left open (CGAL closed) counts as twice CGAL's distance, so leaving holes open never scores well."""
            ratios = []
            for (name, _), cell in rows.items():
                if name != mesh:
                    continue
                mine = [
                    r[label]["mean dist (h)"] if filled(r[label]) else 2 * r[reference]["mean dist (h)"]
                    for r in cell
                    if filled(r[reference])
                ]
                theirs = [r[reference]["mean dist (h)"] for r in cell if filled(r[reference])]
                if theirs:
                    ratios.append(np.mean(mine) / np.mean(theirs))
            return float(np.mean(ratios)) if ratios else float("nan")

        loo = []
        for left in meshes:
            others = [m for m in meshes if m != left]
            chosen = min(
                CANDIDATES, key=lambda c: np.mean([score(c[0], m) for m in others]) if others else 0
            )[0]
            loo.append(
                [
                    left,
                    chosen,
                    score(chosen, left),
                    score("default", left),
                    min(score(c[0], left) for c in CANDIDATES),
                ]
            )
        sections.append(
            (
                "Leave one mesh out (ratio of means against CGAL continuity 2, mean over the sizes)",
                "Each row: the candidate that scores best on every other mesh, its score on the mesh left out, "
                "the default's there, and the best any candidate gets there (known only with the answer).\n\n"
                + markdown_table(
                    ["left out", "chosen on the others", "its score", "default", "best there"], loo
                ),
            )
        )
        every = [[label] + [score(label, m) for m in meshes] for label, _ in CANDIDATES]
        sections.append(
            ("Every candidate on every mesh (same score)", markdown_table(["setting", *meshes], every))
        )
    sections.append(
        (
            "Set-up",
            f"Meshes: {', '.join(meshes)} (the closed, edge-manifold meshes of the data folder asked for). {holes} seeded "
            f"holes (seed {SEED}) per mesh and size, each loop simple; times are the CPU time of a fill, the best "
            f"of {TIMED} (ours on a prebuilt HoleFiller, CGAL on a prebuilt Polyhedron_3; MeshLib one fill, wall "
            "clock) on a shared 2-core machine (read the ratios).",
        )
    )
    sections.append(("Reading (the run of 2026-12-04; check against the tables above after a rerun)", NOTES))
    write_markdown(args.out, "Hole filling on every closed mesh, leave one mesh out", sections)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
