"""The ``o3d-lsmesh demo``: denoise a simulated raw range scan and compare with Open3D's filters.

The scan is :func:`o3d_lsmesh.app.shapes.simulated_range_scan` (fixed seeds, no file). Ours runs
with its defaults; each Open3D filter at the best iteration count of a small sweep, chosen by its
mean distance to the true surface: the peers are told the answer, ours is not.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

from .. import fairing
from .._o3d.io import raycasting_scene, signed_distances, write_mesh_file
from ..core.connectivity import Connectivity
from ..core.errors import InputError
from ..core.progress import Progress
from ..fairing.scan_fairing import triangle_quality
from ..fairing.tuning import SLIVER_QUALITY
from . import render as rendering
from .metrics import rim_mask
from .shapes import simulated_range_scan

__all__ = ["METHODS", "run_demo"]


def _ours(mesh: Any, _: Any) -> Any:
    return fairing.constrained_fairing(mesh)


#: (key, label, function(mesh, parameter), sweep of the parameter: iteration counts; ours has none)
METHODS: list[tuple[str, str, Callable, tuple]] = [
    ("ours", "o3d_lsmesh constrained_fairing (defaults)", _ours, (None,)),
    ("o3d_simple", "Open3D filter_smooth_simple", lambda m, n: m.filter_smooth_simple(n), (1, 2, 3, 5, 10)),
    (
        "o3d_laplacian",
        "Open3D filter_smooth_laplacian",
        lambda m, n: m.filter_smooth_laplacian(number_of_iterations=n),
        (1, 2, 5, 10, 20),
    ),
    (
        "o3d_taubin",
        "Open3D filter_smooth_taubin",
        lambda m, n: m.filter_smooth_taubin(number_of_iterations=n),
        (5, 10, 20, 50, 100),
    ),
]


def _metrics(result: Any, surface_scene: Any, rim: np.ndarray, spacing: float) -> dict:
    """Distances of the vertices to the true surface (in grid spacings), split rim / interior, and slivers."""
    vertices = np.asarray(result.vertices)
    signed = signed_distances(surface_scene, vertices) / spacing
    distance = np.abs(signed)
    quality = triangle_quality(vertices, np.asarray(result.triangles))
    return {
        "mean_distance": float(distance.mean()),
        "rim_distance": float(distance[rim].mean()),
        "interior_distance": float(distance[~rim].mean()),
        "mean_offset": float(signed.mean()),
        "slivers": int((quality < SLIVER_QUALITY).sum()),
    }


def _format_table(rows: list[dict]) -> str:
    header = (
        f"{'method':42s} {'iter':>5s} {'mean':>7s} {'rim':>7s} {'interior':>8s} {'offset':>7s} "
        f"{'slivers':>7s} {'time s':>7s}"
    )
    lines = [header, "-" * len(header)]
    for row in rows:
        if "skipped" in row:
            lines.append(f"{row['label']:42s} skipped: {row['skipped']}")
            continue
        value = "-" if row["value"] is None else str(row["value"])
        lines.append(
            f"{row['label']:42s} {value:>5s} {row['mean_distance']:7.3f} {row['rim_distance']:7.3f} "
            f"{row['interior_distance']:8.3f} {row['mean_offset']:7.3f} {row['slivers']:7d} {row['seconds']:7.3f}"
        )
    return "\n".join(lines)


def _check_out(folder: Path, meshes: list[str]) -> None:
    """Refuse a folder ``out`` that is a file, or holds files of the demo's names that an earlier demo did
    not write (its ``metrics.json`` says it did): the user's own ``scan.ply`` would be replaced."""
    if folder.exists() and not folder.is_dir():
        raise InputError(f"out must be a folder, got the file {str(folder)!r}", param="out")
    present = [
        n for n in [*meshes, "metrics.json", "metrics.md", "before_after.png"] if (folder / n).exists()
    ]
    try:
        earlier = {"spacing", "sweeps"} <= json.loads((folder / "metrics.json").read_text()).keys()
    except (OSError, ValueError, AttributeError):  # none, or not a demo's
        earlier = False
    if present and not earlier:
        raise InputError(
            f"out {str(folder)!r} holds {', '.join(present)}, which the demo would replace and an earlier "
            "demo did not write: name another folder",
            param="out",
        )


def run_demo(
    out: str | os.PathLike = "demo_out",
    *,
    resolution: int = 200,
    noise: float = 0.3,
    seed: int = 0,
    render: bool = True,
    progress: bool = False,
    say: Callable[[str], Any] = print,
) -> dict:
    """Run the demo; return ``{"rows": [...], "spacing": h, "sweeps": {...}, "files": [...]}``.

    ``out``: the folder for ``scan.ply``, ``surface.ply``, one PLY per method, ``metrics.json``,
    ``metrics.md`` and (``render``) ``before_after.png``; ``resolution``, ``noise``, ``seed``: the flags
    of ``o3d-lsmesh demo``; ``say``: what prints each line. Distances: of the vertices to the true
    surface in grid spacings ``h`` (``rim``: the boundary and two rings; ``offset``: the mean signed one,
    negative inward).
    """
    folder = Path(out)
    _check_out(folder, [f"{key}.ply" for key in ("surface", "scan", *(m[0] for m in METHODS))])
    scan, surface = simulated_range_scan(resolution, noise=noise, seed=seed)
    scene = raycasting_scene(np.asarray(surface.vertices), np.asarray(surface.triangles))
    extent = np.ptp(np.asarray(surface.vertices)[:, :2], axis=0).max()
    spacing = 1.05 * extent / (resolution - 1)
    triangles = np.asarray(scan.triangles)
    rim = rim_mask(Connectivity(triangles, len(scan.vertices)), 2)
    components = len(np.asarray(scan.cluster_connected_triangles()[1]))
    say(
        f"o3d-lsmesh demo: a simulated raw range scan of the built-in blob, {len(scan.vertices)} vertices, "
        f"{len(triangles)} triangles, {components} components, range noise {noise} grid spacings (seed {seed})"
    )

    rows = [
        {"key": "scan", "label": "raw scan", "value": None, "seconds": 0.0}
        | _metrics(scan, scene, rim, spacing)
    ]
    results = {"scan": scan}
    sweeps: dict[str, list] = {}
    with Progress(progress, "demo").bar(len(METHODS), unit="method") as bar:
        for key, label, function, values in METHODS:
            bar.set_postfix_str(key)
            try:
                best = None
                sweeps[key] = []
                for value in values:
                    start = time.perf_counter()
                    result = function(scan, value)
                    seconds = time.perf_counter() - start
                    metrics = _metrics(result, scene, rim, spacing)
                    sweeps[key].append((value, metrics["mean_distance"]))
                    if best is None or metrics["mean_distance"] < best[2]["mean_distance"]:
                        best = (value, result, metrics, seconds)
            except Exception as error:  # the demo reports a failing method and carries on
                rows.append(
                    {"key": key, "label": label, "skipped": f"failed: {type(error).__name__}: {error}"}
                )
            else:
                assert best is not None
                value, results[key], metrics, seconds = best
                rows.append({"key": key, "label": label, "value": value, "seconds": seconds} | metrics)
            bar.update(1)

    table = _format_table(rows)
    say(f"\n{table}\n")
    say(
        f"distances of the vertices to the true surface in grid spacings h = {spacing:.5f}: mean, rim (boundary "
        "and two rings), interior; offset = mean signed distance (negative: inward); slivers: triangles of "
        f"quality under {SLIVER_QUALITY}; 'iter' is the best count of each Open3D filter's sweep:"
    )
    for key, sweep in sweeps.items():
        if key != "ours":
            say(f"  {key:14s} " + ", ".join(f"{v}: {d:.3f}" for v, d in sweep))

    files: list[Path] = []
    folder.mkdir(parents=True, exist_ok=True)
    for key, mesh in {"surface": surface, **results}.items():
        write_mesh_file(mesh, folder / f"{key}.ply")
        files.append(folder / f"{key}.ply")
    listed = {k: [[v, d] for v, d in s] for k, s in sweeps.items()}
    payload = {"spacing": spacing, "noise": noise, "seed": seed, "rows": rows, "sweeps": listed}
    (folder / "metrics.json").write_text(json.dumps(payload, indent=2))
    (folder / "metrics.md").write_text("```\n" + table + "\n```\n")
    files += [folder / "metrics.json", folder / "metrics.md"]
    if render:
        panels = {"scan": "raw scan"} | ({"ours": "ours (defaults)"} if "ours" in results else {})
        theirs = [r for r in rows if r["key"].startswith("o3d_") and "skipped" not in r]
        if theirs:  # the best Open3D filter
            peer = min(theirs, key=lambda r: r["mean_distance"])
            panels[peer["key"]] = f"{peer['label'].removeprefix('Open3D ')} ({peer['value']}, its best)"
        keys, titles = list(panels), list(panels.values())
        picture = folder / "before_after.png"
        start = time.perf_counter()
        view: dict[str, Any] = dict(width=420, height=420, view_direction=(0.25, 0.3, 1.0), titles=titles)
        title = "distance to the true surface"
        rendering.render([results[k] for k in keys], picture, reference=surface, colorbar_title=title, **view)
        files.append(picture)
        say(f"picture ({time.perf_counter() - start:.1f} s): {picture}  panels: {' | '.join(titles)}")
    say(f"wrote {len(files)} files to {folder}/")
    return {"rows": rows, "spacing": spacing, "sweeps": sweeps, "files": [str(f) for f in files]}
