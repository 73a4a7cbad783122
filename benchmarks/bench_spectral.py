"""Spectral basis: null-space deflation against plain shift-invert ``eigsh`` (the previous method), side by side.

Raw scans have 40-100 connected components, so the eigenvalue 0 of ``D - A`` has
that multiplicity; plain shift-invert around ``sigma = -1e-6`` makes it a
``c``-fold eigenvalue ``1e6`` of the inverse that ARPACK must resolve before
anything else. ``spectral_basis`` writes the null space down (one normalized
indicator per component) and runs ``eigsh`` on the deflated operator for the
rest, with BLAS on one thread while ARPACK runs. Both run interleaved on the
camel and raw scans for ``k = 20`` (fewer than the components: eigenvalue 0
only) and ``k = 100``. Projections are compared where they are unique (``k``
above the component count); below it any orthonormal null-space basis is
correct and the two methods pick different ones. Writes
``benchmarks/results/spectral.md``; a few minutes on 2 busy cores.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np
import open3d as o3d
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from _common import DATA, REPO, markdown_table, timed, write_markdown
from scipy.sparse import csgraph

from o3d_lsmesh.core.solve import SPDSolver
from o3d_lsmesh.lsmesh.spectral import _SHIFT, combinatorial_laplacian, spectral_basis

SCANS = Path(os.environ.get("O3D_LSMESH_SCANS", REPO.parent / "shared" / "data" / "scans"))


def plain_eigsh(triangles: np.ndarray, n: int, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The previous method: shift-invert ``eigsh`` on ``D - A`` itself, null space included."""
    L = combinatorial_laplacian(triangles, n)
    factor = SPDSolver(L - _SHIFT * sp.identity(n, format="csc"))
    inverse = spla.LinearOperator((n, n), matvec=factor.solve, dtype=np.float64)
    start = np.random.default_rng(0).standard_normal(n)
    values, vectors = spla.eigsh(L, k=k, sigma=_SHIFT, which="LM", OPinv=inverse, v0=start)
    order = np.argsort(values)
    return values[order], vectors[:, order]


def main() -> None:
    meshes = [("camel", DATA / "camel.ply")]
    names = sorted(p.name for p in SCANS.glob("*.ply")) if SCANS.exists() else []
    if not names:
        print(f"no scans in {SCANS} (set O3D_LSMESH_SCANS): camel only")
    if os.environ.get("BENCH_ALL") != "1":
        names = names[:3]
    meshes += [(name, SCANS / name) for name in names]
    rows = []
    for name, path in meshes:
        if not path.exists():
            print(f"skipping {name}: not found")
            continue
        mesh = o3d.io.read_triangle_mesh(str(path))
        V, F = np.asarray(mesh.vertices), np.asarray(mesh.triangles).astype(np.int64)
        n = len(V)
        c = csgraph.connected_components(combinatorial_laplacian(F, n), directed=False)[0]
        for k in (20, 100):
            (vo, Uo), to = timed(lambda F=F, n=n, k=k: plain_eigsh(F, n, k))
            (vn, Un), tn = timed(lambda F=F, n=n, k=k: spectral_basis(F, n, k))
            unique = k > c and vn[k - 1] > 0
            projection = np.abs(Uo @ (Uo.T @ V) - Un @ (Un.T @ V)).max() / np.ptp(V, axis=0).max()
            rows.append(
                [
                    name,
                    n,
                    c,
                    k,
                    to,
                    tn,
                    to / tn,
                    float(np.abs(vo - vn).max()),
                    f"{projection:.1e}" if unique else "n/a (k <= components)",
                ]
            )
            print(rows[-1], flush=True)
    table = markdown_table(
        [
            "mesh",
            "n",
            "components",
            "k",
            "plain eigsh s",
            "deflated s",
            "speed-up",
            "max abs eigenvalue difference",
            "max projection difference / bbox",
        ],
        rows,
    )
    write_markdown(
        "spectral.md",
        "Spectral basis: null-space deflation against plain shift-invert eigsh",
        [("Time and agreement (interleaved, one run)", table + f"\n\nPython {sys.version.split()[0]}.")],
    )


if __name__ == "__main__":
    main()
