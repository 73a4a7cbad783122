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

from o3d_lsmesh.holes import HoleFiller, tuning

RADII = (2.5, 6.0, 15.0)
HOLES = 10
SEED = 37  # fixed before any result of this study was seen
TIMED = 3  # fills timed per tool and hole, the best kept
#: the leave-one-mesh-out candidates: (label, fill_holes_arrays options, and "tuning": constants of
#: o3d_lsmesh.holes.tuning set for the fill); the first is the default
CANDIDATES = [
    ("default", {}),
    ("continuity 1", {"continuity": 1}),
    ("uniform weights", {"weights": "uniform"}),
    ("density 0.7", {"density": 0.7}),
    ("density 1.4", {"density": 1.4}),
    ("cotangent leap 0.05", {"tuning": {"COTANGENT_LEAP": 0.05}}),
    ("cotangent leap 0.2", {"tuning": {"COTANGENT_LEAP": 0.2}}),
]


NOTES = """\
* The run: 2026-12-05 15:45-16:14 UTC, the fill of commit c162009 (this session's three changes: the
  programme's tie rule of c6eee4b, 2 of these 240 holes changed by it, below 1%; a cotangent solve kept
  unless it leaps, 9e14896; the guarded relaxation run again after the flips, c162009), all eight closed
  meshes, 240 holes, the same seeded cuts as the runs of 05499a4 and 9e14896.
* Where ours loses to CGAL continuity 2 (ratio of means above 1): 9 of 24 cells: venus_head 2.5h (1.23,
  interval 0.98-1.39), igea 15h (1.21, 1.00-1.42), igea 6h (1.12), eight 6h (1.08), camel 15h (1.06),
  feline 6h (1.05), venus_head 6h (1.05), horse 15h (1.03), octopus 6h (1.02); every interval but igea
  15h's holds 1. Against the run of 05499a4 (the same 9 cells): eight 6h 1.12 -> 1.08, venus_head 6h
  1.11 -> 1.05, octopus 6h 1.03 -> 1.02, camel 2.5h 0.77 -> 0.70, octopus 2.5h 0.96 -> 0.93, no cell
  worse by more than 1.5% (octopus 2.5h against the run of 9e14896, 0.918 -> 0.932): the cotangent
  solve is no longer dropped for turning a triangle over against a uniform solve that was itself
  folded. CGAL's own continuity 1 is above its continuity 2 on 15 cells, MeshLib on 16.
* What each part of ours gives, swapped on the same holes (scratch runs): CGAL's own triangulation of
  the loop, refined and faired by ours, on eight 6h (a hole across the tube): 1.64 -> 1.17 at 202b2cf,
  the reason the programme now runs over the loop points' 3D Delaunay triangles (Zou et al. 2013, as
  CGAL); the exact ``L^(k+1) x = 0`` system (Liepa's and CGAL's) instead of the least-squares energy:
  within a few percent either way; cotangent weights read off the refined, unfaired patch (CGAL's whole
  pipeline): better on holes across thin parts (eight 6h 1.12 -> 0.98, octopus 6h 1.45 -> 1.03 at
  242a3ff), worse on small ones (camel 2.5h 0.77 -> 0.99, octopus 2.5h 1.26 -> 1.38), and no rule found
  tells the two kinds apart without the truth (results/fill_holes_choice_study.md). Choosing between the
  uniform and the cotangent solve by the lower Willmore energy of each on its own geometry (no constant;
  scratch run at 9e14896): 10 cells above 1, eight 2.5h 0.72 -> 1.05, screwdriver 2.5h 0.85 -> 1.42: not
  adopted.
* The cotangent leap (``holes.tuning.COTANGENT_LEAP``, a cotangent solve moving a vertex by more than
  this fraction of the patch's size from the uniform one is not kept): 0.05, 0.1 and 0.2 as candidates.
  Chosen among the three alone, leaving one mesh out, 0.2 wins on seven folds (0.1 on octopus's); the
  mean left-out score is 0.965 against 0.1's 0.964, and 0.2 is worse on igea (1.112 / 1.058), better on
  camel, eight, horse and octopus by 0.8-5.1%: 0.1 stays. 0.05 keeps more uniform solves: 1.04 mean
  ratio.
* The tangential relaxation (c162009): a vertex's step is kept only where its star's smallest angle does
  not drop, and the patch is relaxed again after the flips and flipped again. Smallest angle at least
  CGAL's on 224 of 237 holes here (187 in the run of 9e14896) and, held out from every choice, on 40 of
  the 47 natural holes of bunny, bun_zipper, camelhead, maxplanck, pig, venus and plane_holes (37); each
  cell's ratio within -0.9% / +1.5%. Tried before it (scratch runs), without the guard: the relaxation
  run to its fixed point (210 of 237 at 05499a4; natural holes 35 against 36) and one more round alone
  (211; natural holes 37 against 37), both lowering pig's worst patches (16.2 -> 13.2, 19.7 -> 14.7,
  17.9 -> 13.5, 21.5 -> 15.8 degrees): a loop edge of 0.005 among new edges of 0.016-0.020, whose apex
  the unguarded steps move away. The cut disks' loops have even edges, the natural ones do not.
* Leave one mesh out over every candidate: density 1.4 is chosen on every fold (as in the runs before).
  On the mesh left out it beats the default on five (camel 0.826 against 0.916, eight 0.927 / 0.969,
  feline 0.911 / 0.936, octopus 0.795 / 0.975, venus_head 1.025 / 1.090) and loses on three (horse 0.945
  / 0.866, igea 1.066 / 1.058, screwdriver 0.922 / 0.904); mean of the left-out scores 0.927 against
  0.964. It costs what the same issue asks for: smallest angle at least CGAL's on 204 of 237 holes (the
  default 224) and time per hole above 2x CGAL's on 9 cells (the default 3). Not adopted: neither
  setting is never worse, and density 1.4 gives up the time target on three times as many cells.
* Left open (every one named in the warning and ``FillReport``): eight 15h twice (the same 27-edge loop:
  the 15h disk takes most of the eight and leaves an open piece, whose loop is taken as its outer
  border; ``fill_border=True`` closes it); venus_head 15h #3 (127 edges): every fill crosses the surface
  (CGAL's fill there crosses with 6 pairs). Every fill ours made is closed, manifold, oriented and free
  of crossings.
* Smallest angle at least CGAL's: 224 of the 237 holes both closed (94.5%); every cell 8/10 or more.
* Time (CPU, prebuilt structures, best of 3): within 2x of CGAL on 21 of 24 cells; igea 2.5h 2.73x (2.96
  against 1.08 ms a hole), octopus 2.5h 2.14x and venus_head 2.5h 2.10x (in the run of 9e14896: 2.58x,
  2.00x and 2.08x; the guarded relaxation's second round costs about 5% on 2.5h holes, 8-17% on
  larger ones). On igea's 2.5h holes 1.3 ms of ours is the copy of the 134k-vertex mesh into the
  returned arrays (profiled: the two concatenations of ``_fill_pass``), which CGAL, editing its
  Polyhedron_3 in place, does not make.
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

    options = dict(options)
    constants = options.pop("tuning", {})

    def run(V, T):
        filler, best = HoleFiller(V, T), np.inf
        kept = {name: getattr(tuning, name) for name in constants}
        try:
            for name, value in constants.items():
                setattr(tuning, name, value)
            for _ in range(TIMED):
                start = time.process_time()
                out = filler.fill(**options)
                best = min(best, time.process_time() - start)
        finally:
            for name, value in kept.items():
                setattr(tuning, name, value)
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
                former = done.get((name, radius), [])
                # a former row of other tools (another candidate list) is filled again, not mixed in
                if k < len(former) and set(former[k]) == {label for label, _ in tools + peers}:
                    rows.setdefault((name, radius), []).append(former[k])
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
    sections.append(("Reading (the run of 2026-12-05; check against the tables above after a rerun)", NOTES))
    write_markdown(args.out, "Hole filling on every closed mesh, leave one mesh out", sections)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
