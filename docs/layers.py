"""Print the package's layers, its modules per layer and every import that runs back up.

Run from a checkout: ``python docs/layers.py`` (or ``python docs/layers.py /path/to/an/old/tree``).
The layer of a module is read off its path (the table below, first match wins), so a module that
moved keeps its role: the before and after of a redesign print side by side.
"""

from __future__ import annotations

import re
import sys
from collections import Counter

import grimp

# (layer, pattern of the module path under o3d_lsmesh.); top layer first
LAYERS = [
    ("app", r"app|_batch_ops|batch|cli|rendering|metrics|demo|shapes|registration|__main__"),
    ("methods", r"fairing|holes|hole_filling|lsmesh|selection|encoding|spectral|summary|laplacian"),
    ("hierarchy", r"hierarchy"),
    ("adapter", r"_o3d"),
    ("core", r"core|topology|_solvers|_validate|_progress|_errors|_collapsed|_ranges|_quantization|_normals"),
    (
        "kernels",
        r"_block_kernel|_feature_kernel|_scan_kernel|_triangulation_kernel|_patch_kernel|_fill_kernel|_types|_compat",
    ),
]


def layer(module: str) -> str:
    tail = module.removeprefix("o3d_lsmesh.")
    for name, pattern in LAYERS:
        if re.match(rf"({pattern})(\.|$)", tail):
            return name
    return "root"


def main() -> None:
    if len(sys.argv) > 1:
        sys.path.insert(0, sys.argv[1])
    graph = grimp.build_graph("o3d_lsmesh", exclude_type_checking_imports=True)
    modules = sorted(m for m in graph.modules if m != "o3d_lsmesh")
    rank = {name: i for i, (name, _) in enumerate(LAYERS)}
    rank["root"] = -1
    per_layer = Counter(layer(m) for m in modules)
    edges = [
        (a, b)
        for a in modules
        for b in graph.find_modules_directly_imported_by(a)
        if b.startswith("o3d_lsmesh.") and b != "o3d_lsmesh"
    ]
    between = Counter((layer(a), layer(b)) for a, b in edges if layer(a) != layer(b))
    print(f"modules {len(modules)}, imports between our modules {len(edges)}")
    for name, _ in LAYERS:
        print(f"  {name:<9} {per_layer[name]:>3} modules")
    print("imports between layers (count):")
    for (a, b), count in sorted(between.items(), key=lambda item: (rank[item[0][0]], rank[item[0][1]])):
        up = "  <- runs back up" if rank[b] < rank[a] else ""
        print(f"  {a:<9} -> {b:<9} {count:>3}{up}")
    # circles: strongly connected groups of modules (Tarjan's algorithm)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    circles = []
    nodes = set(modules)
    succ = {m: [b for a, b in edges if a == m and b in nodes] for m in modules}

    def visit(m: str) -> None:
        index[m] = low[m] = len(index)
        stack.append(m)
        for b in succ[m]:
            if b not in index:
                visit(b)
                low[m] = min(low[m], low[b])
            elif b in stack:
                low[m] = min(low[m], index[b])
        if low[m] == index[m]:
            group = []
            while True:
                b = stack.pop()
                group.append(b)
                if b == m:
                    break
            if len(group) > 1:
                circles.append(sorted(group))

    for m in modules:
        if m not in index:
            visit(m)
    print(f"circles (modules that import each other): {len(circles)}")
    for group in circles:
        print("  " + " <-> ".join(group))
    upward = sorted((a, b) for a, b in edges if rank[layer(b)] < rank[layer(a)] and layer(a) != "root")
    print(f"imports that run back up: {len(upward)}")
    for a, b in upward:
        print(f"  {a} -> {b}")


if __name__ == "__main__":
    main()
