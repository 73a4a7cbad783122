"""Pictures of the committed benchmark tables, for readers who would rather look than read.

Reads the markdown tables the benchmark scripts wrote into ``benchmarks/results/`` (it runs nothing)
and writes beside them:

* ``realscans_denoise.png``: per raw scan (bunny and dragon), the mean distance to the reference of
  ours with its defaults against every peer at its best setting for that scan;
* ``features_denoise.png``: the mean normal angle (theta) per benchmark mesh, ``method="features"``
  and the default against the best classical peer and GCN-Denoiser's released results;
* ``fill_holes_study.png``: per closed mesh and hole size, the ratio of mean distances ours / CGAL
  continuity 2 with its bootstrap interval.

Run: ``python benchmarks/plot_results.py`` (needs matplotlib). A missing table is skipped with a note.
"""

from __future__ import annotations

import re

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from _common import RESULTS


def table(name: str, heading: str) -> list[dict[str, str]]:
    """The rows of the first table under the ``## heading`` of ``results/name``, as dicts by column."""
    path = RESULTS / name
    if not path.exists():
        print(f"skipping {name}: not in {RESULTS}")
        return []
    text = path.read_text()
    if f"## {heading}" not in text:
        print(f"skipping {name}: no section {heading!r}")
        return []
    section = text.split(f"## {heading}", 1)[1].split("\n## ", 1)[0]
    lines = [line for line in section.splitlines() if line.startswith("|")]
    header = [cell.strip() for cell in lines[0].strip("|").split("|")]
    return [dict(zip(header, (cell.strip() for cell in line.strip("|").split("|")))) for line in lines[2:]]


def number(cell: str) -> float:
    found = re.match(r"\s*(-?[\d.]+)", cell)
    return float(found.group(1)) if found else float("nan")


def realscans() -> None:
    fig, axes = plt.subplots(1, 2, figsize=(14, 4.8), gridspec_kw={"width_ratios": [10, 16]})
    peers = ["Open3D simple", "Open3D Laplacian", "Open3D Taubin", "MeshLab HC", "bilateral normal filtering"]
    for ax, obj in zip(axes, ("bunny", "dragon")):
        rows = table("realscans_denoise.md", f"{obj}: per scan, each peer at its best setting (mean um)")
        if not rows:
            continue
        names = [r["scan"].replace(".ply", "").replace("dragon", "") for r in rows]
        x = range(len(rows))
        best = [min(number(r[p]) for p in peers if p in r) for r in rows]
        ax.bar([i - 0.3 for i in x], [number(r["raw um"]) for r in rows], 0.3, color="0.8", label="raw scan")
        ax.bar(list(x), best, 0.3, color="tab:orange", label="best peer at its best setting, per scan")
        ours = [number(r["ours (defaults)"]) for r in rows]
        ax.bar([i + 0.3 for i in x], ours, 0.3, color="tab:blue", label="ours, defaults")
        ax.set_xticks(list(x), names, rotation=60, ha="right", fontsize=8)
        ax.set_ylabel("mean distance to the reference surface (um)")
        ax.set_title(f"{obj}: {len(rows)} raw range scans")
        ax.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    fig.savefig(RESULTS / "realscans_denoise.png", dpi=110)
    plt.close(fig)


def features() -> None:
    heading = "Theta (degrees) and mean vertex distance (mean edge lengths), each peer at its best setting"
    rows = table("features_denoise.md", heading)
    if not rows:
        return
    classical = [
        "Open3D simple",
        "Open3D Laplacian",
        "Open3D Taubin",
        "bilateral normal filtering",
        "MeshLab two-step",
        "MeshLib denoiseViaNormals",
    ]
    fig, ax = plt.subplots(figsize=(12, 4.5))
    x = range(len(rows))
    series = [
        ("features (ours)", [number(r["features (ours)"]) for r in rows], "tab:blue"),
        ("auto (ours)", [number(r["auto (ours)"]) for r in rows], "tab:cyan"),
        ("best classical peer", [min(number(r[c]) for c in classical if c in r) for r in rows], "tab:orange"),
        ("GCN-Denoiser (released results)", [number(r.get("GCN-Denoiser", "-")) for r in rows], "tab:green"),
    ]
    for k, (label, values, color) in enumerate(series):
        ax.bar([i + 0.2 * (k - 1.5) for i in x], values, 0.2, label=label, color=color)
    ax.set_xticks(list(x), [r["mesh"] for r in rows], rotation=30, ha="right", fontsize=8)
    ax.set_ylabel("mean angle to the true face normals (degrees)")
    ax.set_title("Denoising benchmark meshes with ground truth (lower is better)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(RESULTS / "features_denoise.png", dpi=110)
    plt.close(fig)


def fill_holes() -> None:
    rows = table("fill_holes_study.md", "Per mesh and size (mean distance to the removed surface, in h)")
    key = next((k for k in (rows[0] if rows else {}) if k.startswith("ours / CGAL c2")), None)
    if key is None:
        return
    fig, ax = plt.subplots(figsize=(12, 4.5))
    labels, ratios, low, high = [], [], [], []
    for r in rows:
        labels.append(f"{r['mesh']} {r['size']}")
        ratios.append(number(r[key]))
        interval = re.match(r"([\d.]+)-([\d.]+)", r.get("95% interval", ""))
        low.append(ratios[-1] - float(interval.group(1)) if interval else 0.0)
        high.append(float(interval.group(2)) - ratios[-1] if interval else 0.0)
    x = range(len(rows))
    colors = ["tab:blue" if v <= 1 else "tab:red" for v in ratios]
    ax.bar(list(x), ratios, 0.6, color=colors, yerr=[low, high], capsize=2)
    ax.axhline(1.0, color="k", lw=0.8)
    ax.set_xticks(list(x), labels, rotation=60, ha="right", fontsize=8)
    ax.set_ylabel("mean distance, ours / CGAL continuity 2")
    ax.set_title("Hole filling on every closed mesh: below 1 ours is closer (95% bootstrap intervals)")
    fig.tight_layout()
    fig.savefig(RESULTS / "fill_holes_study.png", dpi=110)
    plt.close(fig)


def main() -> int:
    realscans()
    features()
    fill_holes()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
