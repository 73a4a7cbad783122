"""Barycenter-constrained fairing for raw range scans: the default energy of ``constrained_fairing``.

The global penalty form of Liu et al.'s eq. 5 with the boundary freed, the
barycenters weighted by their noise, a small membrane term and one twicing
step (Tukey's bias correction), all with one factorization::

    E(X) = |K X|^2 + mu sum_t w_t |h_t (X - X0)|^2 + lambda sum_(i,j) |x_i - x_j|^2

* ``K`` is the uniform Laplacian of *every* referenced vertex (eq. 3; a
  boundary vertex keeps its one-sided row), so the boundary moves with the
  surface instead of being held at its noisy scanned position.
* ``h_t`` is triangle ``t``'s row of the triangle-vertex incidence (``h_t X``
  is three times its barycenter); every triangle is penalised, with weight
  ``w_t = 1`` inside and ``w_t = boundary_weight`` for a triangle with a
  boundary vertex. A barycenter is a measurement and its weight is its
  inverse noise variance: a scanner's samples at the silhouette (grazing
  angles) carry 2.5-4 times the interior's error, so their barycenters are
  trusted about ten times less.
* The membrane term (uniform weights, one per edge) damps the mid-frequency,
  scanline-correlated noise of a range scanner that the thin-plate term
  ``|K X|^2`` leaves in place.

Minimizing gives the linear filter ``X1 = S X0`` with
``S = (K^T K + mu H^T W H + lambda G)^-1 mu H^T W H`` (``G`` the graph
Laplacian); the result is the twiced filter ``X = X1 + S (X0 - X1)`` (one
more back-substitution with the same factor), which puts back the
low-frequency part of what ``S`` removed, i.e. the shrinkage of the membrane.

Every term is quadratic in coordinate differences with dimensionless
weights, so the result is equivariant under rigid motions and uniform
scaling; no parameter depends on the mesh's size.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .._solvers import SPDSolver
from ..topology import unique_edges

__all__ = [
    "SCAN_BOUNDARY_WEIGHT",
    "SCAN_MEMBRANE",
    "SCAN_MU",
    "SCAN_THIN_PLATE",
    "ScanFairingSolver",
    "ScanSystem",
    "measured_boundary_weight",
    "scan_system",
]

#: Barycenter penalty weight of the scan energy (measured on the raw scans,
#: see benchmarks/results/realscans_denoise.md).
SCAN_MU = 0.03
#: Membrane weight ``lambda`` of the scan energy.
SCAN_MEMBRANE = 0.45
#: Weight ``kappa`` of the thin-plate term ``|K X|^2`` (Liu et al.'s energy).
SCAN_THIN_PLATE = 1.0
#: Lowest barycenter weight of triangles touching the boundary, relative to the
#: interior's (a ragged scan silhouette: see :func:`measured_boundary_weight`).
SCAN_BOUNDARY_WEIGHT = 0.1
# Expected ratio (boundary curve / interior) of the mean squared uniform Laplacian for i.i.d. noise of
# one variance: a curve vertex's (x_(i-1) + x_(i+1)) / 2 - x_i has variance 1.5 sigma^2, an interior
# vertex of valence 6 has (1 + 1/6) sigma^2.
_IID_BOUNDARY_RATIO = 1.5 / (1.0 + 1.0 / 6.0)


def measured_boundary_weight(vertices: np.ndarray, triangles: np.ndarray) -> float:
    """The boundary triangles' barycenter weight ``w`` estimated from the noise of the input.

    ``w = clip(c (9/7) E_int / E_bd, 0.1, c)``, with ``E_int`` the mean of
    ``|L x_i|^2`` over interior vertices (``L`` the uniform Laplacian over
    every edge), ``E_bd`` the mean over boundary vertices of the squared
    uniform Laplacian *along the boundary curve* (neighbours across edges of
    one triangle), and ``c >= 1`` the coverage ratio: the mean number of
    triangles at an interior vertex over that at a boundary vertex (about 2).
    For i.i.d. noise of one variance ``E_bd / E_int = 9/7`` (valence 6), so
    ``(9/7) E_int / E_bd`` is the estimated inverse ratio of the boundary's
    to the interior's noise variance; ``c`` gives a boundary vertex, which
    lies in about half as many barycenters, the data weight of an interior
    vertex when its noise is the interior's. Both energies are quadratic in
    coordinate differences: ``w`` is invariant under rigid motions and
    uniform scaling. Returns 1 when the mesh has no boundary, and ``c`` for
    a straight noiseless one.

    Parameters
    ----------
    vertices : (n, 3) float64
    triangles : (m, 3) int64

    Returns
    -------
    float in ``[SCAN_BOUNDARY_WEIGHT, c]``.

    Examples
    --------
    >>> import numpy as np
    >>> g = np.stack(np.meshgrid(np.arange(30.0), np.arange(30.0), indexing="ij"), -1).reshape(-1, 2)
    >>> F = np.array([[i * 30 + j, i * 30 + j + 30, i * 30 + j + 1] for i in range(29) for j in range(29)]
    ...              + [[i * 30 + j + 1, i * 30 + j + 30, i * 30 + j + 31] for i in range(29) for j in range(29)])
    >>> V = np.c_[g, np.zeros(900)] + np.random.default_rng(0).normal(0.0, 0.3, (900, 3))
    >>> measured_boundary_weight(V, F) > 1.5  # i.i.d. noise: a rim vertex weighs like an interior one
    True
    >>> ragged = V.copy(); rim = (g == 0).any(1) | (g == 29).any(1)
    >>> ragged[rim] += np.random.default_rng(1).normal(0.0, 2.0, (rim.sum(), 3))
    >>> measured_boundary_weight(ragged, F)  # a scan's silhouette: the rim 7 times noisier
    0.1
    """
    n = len(vertices)
    edges, counts, _ = unique_edges(triangles, n)
    on_curve = edges[counts == 1]
    if not len(on_curve):
        return 1.0
    boundary = np.zeros(n, dtype=bool)
    boundary[on_curve.ravel()] = True
    valence = np.bincount(edges.ravel(), minlength=n)
    interior = (valence > 0) & ~boundary
    if not interior.any():
        return 1.0
    in_triangles = np.bincount(triangles.ravel(), minlength=n)
    coverage = max(1.0, float(in_triangles[interior].mean() / in_triangles[boundary].mean()))

    def mean_square_laplacian(pairs, mask):
        degree = np.bincount(pairs.ravel(), minlength=n).astype(np.float64)
        total = np.zeros((n, 3))
        np.add.at(total, pairs[:, 0], vertices[pairs[:, 1]])
        np.add.at(total, pairs[:, 1], vertices[pairs[:, 0]])
        lap = total[mask] / degree[mask, None] - vertices[mask]
        return float((lap * lap).sum(axis=1).mean())

    curve_energy = mean_square_laplacian(on_curve, boundary)
    if curve_energy <= 0.0:
        return coverage
    ratio = coverage * _IID_BOUNDARY_RATIO * mean_square_laplacian(edges, interior) / curve_energy
    return float(np.clip(ratio, SCAN_BOUNDARY_WEIGHT, coverage))


@dataclass(frozen=True)
class ScanSystem:
    """The scan energy as weighted least-squares equations, per coordinate.

    ``E(X) = |R X - T|^2`` with the stacked rows ``R = [sqrt(mu W) H;
    sqrt(lambda) D; (unit rows); sqrt(kappa) K]`` (``D`` the ``(e, n)``
    edge-difference matrix; the thin-plate rows only when ``kappa > 0``) and
    targets ``T = [sqrt(mu W) H X0; 0; ...]``, so the normal matrix is
    ``R^T R = mu H^T W H + lambda D^T D + kappa K^T K`` (``D^T D`` is the
    graph Laplacian ``G``). Unreferenced vertices get a unit row of their
    own, so the system is positive definite and leaves them in place.

    Attributes
    ----------
    rows : (m + e + u [+ n], n) CSR
        ``R`` (``u`` unreferenced vertices); its first ``m`` rows are ``penalty``.
    penalty : (m, n) CSR
        ``sqrt(mu W) H``, the rows that carry the targets.
    referenced, boundary : (n,) bool
    triangle_weight : (m,) float64
        ``w_t``.
    """

    rows: sp.csr_matrix
    penalty: sp.csr_matrix
    referenced: np.ndarray
    boundary: np.ndarray
    triangle_weight: np.ndarray

    def normal_matrix(self) -> sp.csc_matrix:
        """``R^T R``, ``(n, n)`` CSC (what the solver factors, formed here only for checks)."""
        return (self.rows.T @ self.rows).tocsc()

    def normal_rhs(self, positions0: np.ndarray) -> np.ndarray:
        """``R^T T = mu H^T W H X0``, ``(n, 3)``."""
        return self.penalty.T @ (self.penalty @ positions0)


def scan_system(
    triangles: np.ndarray,
    n: int,
    *,
    mu: float,
    membrane: float,
    boundary_weight: float,
    thin_plate: float = SCAN_THIN_PLATE,
) -> ScanSystem:
    """The least-squares rows of the scan energy for ``(m, 3) int64`` triangles on ``n`` vertices.

    No manifold condition: an edge of three or more triangles is an interior
    edge (it is not on the boundary), a vertex joining several fans has the
    union of their neighbours as its 1-ring. Built from one edge list, in
    ``O(n + m)``.
    """
    m = len(triangles)
    edges, counts, _ = unique_edges(triangles, n)
    e = len(edges)
    lo, hi = edges[:, 0], edges[:, 1]
    boundary = np.zeros(n, dtype=bool)
    boundary[edges[counts == 1].ravel()] = True
    valence = np.bincount(edges.ravel(), minlength=n)
    referenced = valence > 0
    unreferenced = np.flatnonzero(~referenced)
    inverse = np.zeros(n)
    np.divide(1.0, valence, out=inverse, where=referenced)
    weight = np.where(boundary[triangles].any(axis=1), float(boundary_weight), 1.0)  # (m,) w_t
    root = np.sqrt(mu * weight)
    membrane_root = np.sqrt(membrane)
    ref_rows = np.flatnonzero(referenced)
    # rows [0, m): sqrt(mu w_t) at t's corners; [m, m+e): sqrt(lambda) (x_lo - x_hi); a unit row per
    # unreferenced vertex; then, with a thin-plate weight kappa, sqrt(kappa) K (row i: 1 at i, -1/n_i at
    # each neighbour)
    u = len(unreferenced)
    row = [np.repeat(np.arange(m), 3), m + np.arange(e), m + np.arange(e), m + e + np.arange(u)]
    col = [triangles.ravel(), lo, hi, unreferenced]
    data = [np.repeat(root, 3), np.full(e, membrane_root), np.full(e, -membrane_root), np.ones(u)]
    count = m + e + u
    if thin_plate > 0.0:
        plate = np.sqrt(thin_plate)
        row += [count + ref_rows, count + lo, count + hi]
        col += [ref_rows, hi, lo]
        data += [np.full(len(ref_rows), plate), -plate * inverse[lo], -plate * inverse[hi]]
        count += n
    rows = sp.csr_matrix((np.concatenate(data), (np.concatenate(row), np.concatenate(col))), shape=(count, n))
    corners = np.arange(0, 3 * m + 1, 3)
    penalty = sp.csr_matrix((np.repeat(root, 3), triangles.ravel(), corners), shape=(m, n))
    return ScanSystem(rows, penalty, referenced, boundary, weight)


class ScanFairingSolver:
    """The scan energy factored once; :meth:`solve` faires positions with it.

    Parameters
    ----------
    triangles : (m, 3) int64
    n : int
        Vertex count (unreferenced vertices stay where they are).
    mu, membrane, boundary_weight : float
        ``mu``, ``lambda`` and the boundary triangles' ``w_t`` of the energy
        (see the module docstring).

    Notes
    -----
    ``R^T R`` is positive definite: on each connected component the only
    null vector of ``K^T K`` and ``G`` is the constant, and
    ``1^T H^T W H 1 = 9 sum_t w_t > 0``; unreferenced vertices have their
    unit rows. CHOLMOD factors ``R^T R`` from the rows without forming the
    product (:class:`~o3d_lsmesh._solvers.SPDSolver` ``product_of``), with
    the AMD ordering (on these meshes as little fill as METIS, found faster).
    The object pickles (the solver refactors on load) and its solves are
    serialized by the solver's lock.
    """

    def __init__(
        self,
        triangles: np.ndarray,
        n: int,
        *,
        mu: float,
        membrane: float,
        boundary_weight: float,
        thin_plate: float = SCAN_THIN_PLATE,
    ) -> None:
        self.mu = float(mu)
        self.membrane = float(membrane)
        self.system = scan_system(
            triangles,
            n,
            mu=self.mu,
            membrane=self.membrane,
            boundary_weight=boundary_weight,
            thin_plate=thin_plate,
        )
        self._solver = SPDSolver(product_of=self.system.rows.T.tocsc(), ordering="amd")

    def filter(self, positions0: np.ndarray) -> np.ndarray:
        """``S X0``: the minimizer of the energy for targets ``X0``, ``(n, 3)`` (unreferenced rows kept)."""
        out = self._solver.solve(self.system.normal_rhs(positions0))
        unused = ~self.system.referenced
        out[unused] = positions0[unused]
        return out

    def solve(
        self, positions0: np.ndarray, *, number_of_iterations: int = 1, twice: bool = True
    ) -> np.ndarray:
        """``number_of_iterations`` filter passes (targets re-taken each time), then the twicing step."""
        positions = np.array(positions0, dtype=np.float64)
        for _ in range(number_of_iterations):
            positions = self.filter(positions)
        if twice and number_of_iterations:
            positions = positions + self.filter(positions0 - positions)
        return positions
