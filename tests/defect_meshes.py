"""Generated meshes with the defects of raw scans, as ``(vertices (n, 3) float64, triangles (m, 3) int64)``.

Each generator builds a small noisy height-field patch (like a range scan) and
adds one kind of defect; :data:`DEFECTS` maps a name to its generator and
:func:`all_defects` combines every kind in one mesh. The expected counts of
each defect are returned so that tests can check ``topology_summary`` against
the construction rather than against the code under test.
"""

from __future__ import annotations

import numpy as np


def patch(nx: int = 12, ny: int = 10, *, seed: int = 0, noise: float = 0.01, origin=(0.0, 0.0)):
    """A noisy triangulated height field on a grid (spacing 0.1), consistently oriented (+z normals)."""
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid(np.arange(nx) * 0.1 + origin[0], np.arange(ny) * 0.1 + origin[1], indexing="xy")
    z = 0.2 * np.sin(2 * x) * np.cos(3 * y)
    vertices = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1) + rng.normal(0, noise, (nx * ny, 3))
    index = np.arange(nx * ny).reshape(ny, nx)
    a, b, c, d = (
        index[:-1, :-1].ravel(),
        index[:-1, 1:].ravel(),
        index[1:, :-1].ravel(),
        index[1:, 1:].ravel(),
    )
    triangles = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])
    return vertices, triangles.astype(np.int64)


def _drop_cells(triangles: np.ndarray, nx: int, ny: int, cells) -> np.ndarray:
    per_half = (nx - 1) * (ny - 1)
    drop = []
    for j, i in cells:
        cell = j * (nx - 1) + i
        drop += [cell, cell + per_half]
    keep = np.setdiff1d(np.arange(len(triangles)), drop)
    return triangles[keep]


def bowtie(seed: int = 0):
    """Two patches sharing one corner vertex: a vertex joining two fans, with a pinched boundary."""
    V1, F1 = patch(6, 6, seed=seed)
    V2, F2 = patch(6, 6, seed=seed + 1, origin=(0.5, 0.5))
    shared = 35  # last vertex of the first patch, (0.5, 0.5)
    index = np.arange(len(V2)) + len(V1) - 1
    index[0] = shared  # first vertex of the second patch is (0.5, 0.5): not copied
    vertices = np.vstack([V1, V2[1:]])
    triangles = np.vstack([F1, index[F2]])
    return vertices, triangles, {"nonmanifold_vertices": 1, "components": 1, "surface_pieces": 2}


def fin(seed: int = 0):
    """A patch with one more triangle on an interior edge: an edge of three triangles (a fin)."""
    V, F = patch(8, 8, seed=seed)
    a, b = 27, 36  # the diagonal of cell (row 3, column 3): an interior edge of two triangles
    assert any({a, b} <= set(t) for t in F.tolist())
    tip = V[[a, b]].mean(axis=0) + [0.0, 0.0, 0.3]
    vertices = np.vstack([V, tip])
    triangles = np.vstack([F, [[a, b, len(V)]]])  # one more: three triangles on (a, b)
    return vertices, triangles, {"nonmanifold_edges": 1}


def pinched_boundary(seed: int = 0):
    """Two holes touching at a vertex: cells (3, 3) and (4, 4) removed, they share vertex (4, 4)."""
    nx = ny = 9
    V, F = patch(nx, ny, seed=seed)
    F = _drop_cells(F, nx, ny, [(3, 3), (4, 4)])
    return V, F, {"nonmanifold_vertices": 1, "boundary_components": 2}


def isolated_triangles(seed: int = 0):
    """A patch plus isolated triangles, a valence-2 pillow and a sliver strip of three triangles."""
    V, F = patch(8, 8, seed=seed)
    rng = np.random.default_rng(seed + 7)
    extra_v, extra_f = [], []
    base = len(V)
    for k in range(4):  # isolated triangles: every vertex of valence 2
        corner = rng.normal(0, 0.05, (3, 3)) + [2.0 + k, 0.0, 0.0]
        extra_v.append(corner)
        extra_f.append(np.arange(3) + base + 3 * k)
    base += 12
    pillow = np.array([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0.0]]) + [0, 2.0, 0]
    extra_v.append(pillow)
    extra_f += [np.array([base, base + 1, base + 2]), np.array([base, base + 2, base + 1])]
    base += 3
    strip = np.array([[0, 0, 0], [1, 0, 0], [0, 0.01, 0], [1, 0.01, 0], [2, 0.0, 0]]) + [0, 3.0, 0]
    extra_v.append(strip)
    extra_f += [
        np.array([base, base + 1, base + 3]),
        np.array([base, base + 3, base + 2]),
        np.array([base + 1, base + 4, base + 3]),
    ]
    vertices = np.vstack([V, *extra_v])
    triangles = np.vstack([F, np.array(extra_f)])
    return vertices, triangles, {"components": 7}


def duplicated_seam(seed: int = 0):
    """A patch cut along a column whose seam vertices are duplicated, not merged: two parts, coincident rims."""
    nx = ny = 8
    V, F = patch(nx, ny, seed=seed)
    seam = np.arange(ny) * nx + 4  # column 4
    copy = np.arange(len(seam)) + len(V)
    vertices = np.vstack([V, V[seam]])
    # triangles right of the seam use the copies
    right = V[F].mean(axis=1)[:, 0] > V[seam[0], 0]
    remap = np.arange(len(V))
    remap[seam] = copy
    triangles = F.copy()
    triangles[right] = remap[F[right]]
    return vertices, triangles, {"components": 2, "boundary_loops": 2}


def degenerate_triangles(seed: int = 0):
    """A patch with zero-area triangles: a vertex moved onto a neighbour and one onto an edge's line."""
    V, F = patch(8, 8, seed=seed)
    V = V.copy()
    V[10] = V[11]  # coincident vertices: the triangles holding both become needles of zero area
    V[27] = 0.5 * (V[26] + V[28])  # collinear with its left and right neighbours
    return V, F, {}


def flipped_triangles(seed: int = 0):
    """A patch with a few triangles reversed: inconsistently oriented neighbours."""
    V, F = patch(8, 8, seed=seed)
    F = F.copy()
    for t in (5, 20, 40, 60):
        F[t] = F[t, ::-1]
    return V, F, {}


DEFECTS = {
    "bowtie": bowtie,
    "fin": fin,
    "pinched_boundary": pinched_boundary,
    "isolated_triangles": isolated_triangles,
    "duplicated_seam": duplicated_seam,
    "degenerate_triangles": degenerate_triangles,
    "flipped_triangles": flipped_triangles,
}


def all_defects(seed: int = 0):
    """Every defect kind side by side in one mesh (translated apart)."""
    vertices, triangles = [], []
    offset = 0
    for k, make in enumerate(DEFECTS.values()):
        V, F, _ = make(seed)
        vertices.append(V + [0.0, 0.0, 3.0 * k])
        triangles.append(F + offset)
        offset += len(V)
    return np.vstack(vertices), np.vstack(triangles), {}
