"""Barycenter-constrained fairing for raw range scans: the default energy of ``constrained_fairing``.

The global penalty form of Liu et al.'s eq. 5 with the boundary freed, the
barycenters weighted by their noise, a small membrane term and one twicing
step (Tukey's bias correction), all with one linear system::

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
more solve of the same system), which puts back the
low-frequency part of what ``S`` removed, i.e. the shrinkage of the membrane.

Every term is quadratic in coordinate differences with dimensionless
weights, so the result is equivariant under rigid motions and uniform
scaling; no parameter depends on the mesh's size. The weights are measured
on the mesh (:func:`scan_parameters`: ``mu`` from its detail-to-noise ratio),
and the default finishes with :func:`relax_rim`, a tangential relaxation of
the triangles the solve squeezes at a scan's rim.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp

from .._collapsed import collapsed_triangles
from .._normals import area_weighted_normals
from .._progress import stages
from .._solvers import SPDSolver, gram_matrix, solver_backend
from ..topology import edge_structure, ring_pattern

__all__ = [
    "MU_RANGE",
    "NOISE_MU_POWER",
    "NOISE_MU_SCALE",
    "SCAN_BOUNDARY_FRACTION",
    "SCAN_BOUNDARY_WEIGHT",
    "SCAN_ITERATIVE_VERTICES",
    "SCAN_MEMBRANE",
    "SCAN_MU",
    "SCAN_REDUCTION",
    "SCAN_RIM_MU",
    "SCAN_RIM_RATIO",
    "SLIVER_QUALITY",
    "NoiseEstimate",
    "ScanFairingSolver",
    "ScanParameters",
    "ScanSystem",
    "measured_boundary_weight",
    "measured_noise",
    "relax_rim",
    "rim_noise_ratio",
    "scan_denoise",
    "scan_likeness",
    "scan_normal_matrix",
    "scan_parameters",
    "scan_system",
    "triangle_quality",
]

#: Scale of a range scan's interior barycenter weight, ``mu = SCAN_MU (g / sigma)^2``: the Wiener weight
#: of a signal of detail ``g`` in noise ``sigma`` (:func:`measured_noise`), so that detail above the noise
#: is held (fitted on each object, scored on the other: benchmarks/results/realscans_denoise.md).
SCAN_MU = 0.06
#: Barycenter weight ``mu w_t`` of a range scan's rim triangles over their measured relative weight ``w``
#: (:func:`measured_boundary_weight`): the rim is smoothed as strongly whatever the interior's detail;
#: also the least weight of the interior's barycenters (they are never trusted less than the rim's).
SCAN_RIM_MU = 0.02
#: A triangle whose quality ``4 sqrt(3) area / (sum of squared edges)`` (1 equilateral) falls below this
#: is a sliver (a 1:20 isosceles needle or a flattened cap): :func:`relax_rim` keeps none of its own making.
SLIVER_QUALITY = 0.05
#: Membrane weight ``lambda`` of the scan energy.
SCAN_MEMBRANE = 0.45
#: Lowest barycenter weight of triangles touching the boundary, relative to the
#: interior's (a ragged scan silhouette: see :func:`measured_boundary_weight`).
SCAN_BOUNDARY_WEIGHT = 0.1
# Expected ratio (boundary curve / interior) of the mean squared uniform Laplacian for i.i.d. noise of
# one variance: a curve vertex's (x_(i-1) + x_(i+1)) / 2 - x_i has variance 1.5 sigma^2, an interior
# vertex of valence 6 has (1 + 1/6) sigma^2.
_IID_BOUNDARY_RATIO = 1.5 / (1.0 + 1.0 / 6.0)
#: Rim data weights (:func:`rim_noise_ratio`) at which :func:`scan_likeness` is 1 and 0.
SCAN_RIM_RATIO = (0.3, 0.6)
#: Boundary-vertex fractions at which :func:`scan_likeness` is 0 and 1.
SCAN_BOUNDARY_FRACTION = (0.01, 0.03)
#: ``mu = NOISE_MU_SCALE (g / sigma)^NOISE_MU_POWER`` for independent noise (:func:`scan_parameters`).
NOISE_MU_SCALE = 0.8
NOISE_MU_POWER = 2.5
#: Range of that ``mu``.
MU_RANGE = (3e-3, 1.0)
#: Vertex count from which ``solver="auto"`` solves the scan energy by conjugate gradients preconditioned
#: by the matrix's incomplete Cholesky factor (IC(0)) instead of factoring it. The matrix's data term sits
#: on every vertex, so its condition number does not grow with the mesh: 6-11 iterations a solve from a
#: few hundred vertices to 1.4M, linear work. Measured (whole calls, medians): faster than the factor
#: at every size, 0.65-0.86x below 7k vertices, 0.47x at 13k, 0.45-0.6x on the ten 30k-40k scans,
#: 0.37x at 1.4M, level on a soup of 500-vertex pieces (150k); below this count the gain is a few
#: milliseconds and the factor, exact, is kept (benchmarks/results/realscans_denoise_speed.md).
SCAN_ITERATIVE_VERTICES = 5_000
#: The iterative path stops each solve when its residual is this fraction of its residual at the start
#: (the scan): the displacement is then within 5e-5 to 1.3e-4 mean edge lengths RMS of the exact
#: minimizer's (at most 6e-3 at a vertex) on the ten raw scans, a thousand times below the noise it
#: removes, and the mean distance to the reference within 0.001 um of the factor's (1e-3: 2e-3 to
#: 5e-3 RMS, 0.2 at a vertex, 0.03 um).
SCAN_REDUCTION = 1e-4


class _Structure(NamedTuple):
    edges: np.ndarray  # (e, 2) int32 (int64 past 2**31 half-edges), lo < hi, sorted
    counts: np.ndarray  # (e,) triangles on each edge
    boundary: np.ndarray  # (n,) bool, on an edge of one triangle
    valence: np.ndarray  # (n,) int64 edge neighbours
    halfedge_edge: np.ndarray  # (3m,) edge of half-edge ``a * m + t`` (triangle t, corners a, a + 1)


def _structure(triangles: np.ndarray, n: int) -> _Structure:
    # int32 indices where they fit: half the memory traffic of int64 at scan sizes
    es = edge_structure(triangles, n)
    boundary = np.zeros(n, dtype=bool)
    boundary[es.edges[es.counts == 1].ravel()] = True
    return _Structure(es.edges, es.counts, boundary, np.bincount(es.edges.ravel(), minlength=n), es.inverse)


def _mean_square_laplacian(vertices: np.ndarray, pairs: np.ndarray, mask: np.ndarray) -> float:
    """Mean over the ``mask`` vertices of ``|mean of the pairs-neighbours - x_i|^2`` (bincount, not ``np.add.at``)."""
    n = len(vertices)
    lo, hi = pairs[:, 0], pairs[:, 1]
    degree = np.bincount(pairs.ravel(), minlength=n)[mask].astype(np.float64)
    total = np.empty((int(mask.sum()), 3))
    for k in range(3):
        total[:, k] = (
            np.bincount(lo, vertices[hi, k], minlength=n) + np.bincount(hi, vertices[lo, k], minlength=n)
        )[mask]
    lap = total / degree[:, None] - vertices[mask]
    return float((lap * lap).sum(axis=1).mean())


def rim_noise_ratio(
    vertices: np.ndarray, triangles: np.ndarray, *, structure: _Structure | None = None
) -> tuple[float, float]:
    """The rim's data weight before clipping, ``c (9/7) E_int / E_bd``, and the coverage ratio ``c``.

    See :func:`measured_boundary_weight` (which clips the first to
    ``[SCAN_BOUNDARY_WEIGHT, c]``). Returns ``(inf, 1)`` for a mesh without a
    boundary or without an interior vertex, ``(c, c)`` for a noiseless
    straight rim.
    """
    n = len(vertices)
    st = _structure(triangles, n) if structure is None else structure
    on_curve = st.edges[st.counts == 1]
    interior = (st.valence > 0) & ~st.boundary
    if not len(on_curve) or not interior.any():
        return float("inf"), 1.0
    in_triangles = np.bincount(triangles.ravel(), minlength=n)
    coverage = max(1.0, float(in_triangles[interior].mean() / in_triangles[st.boundary].mean()))
    curve_energy = _mean_square_laplacian(vertices, on_curve, st.boundary)
    if curve_energy <= 0.0:
        return coverage, coverage
    interior_energy = _mean_square_laplacian(vertices, st.edges, interior)
    return coverage * _IID_BOUNDARY_RATIO * interior_energy / curve_energy, coverage


def measured_boundary_weight(vertices: np.ndarray, triangles: np.ndarray) -> float:
    """The boundary triangles' barycenter weight ``w`` estimated from the noise of the input.

    ``w = clip(c (9/7) E_int / E_bd, 0.1, c)``: ``E_int`` the mean of ``|L x_i|^2`` over interior
    vertices (uniform Laplacian), ``E_bd`` the mean over boundary vertices of the squared uniform
    Laplacian *along the boundary curve*, ``c >= 1`` the mean number of triangles at an interior
    vertex over that at a boundary vertex (about 2). For i.i.d. noise ``E_bd / E_int = 9/7``, so
    ``(9/7) E_int / E_bd`` estimates the interior's over the boundary's noise variance, and ``c``
    gives a rim vertex (in half as many barycenters) an interior vertex's data weight. Invariant
    under rigid motions and uniform scaling. 1 without a boundary, ``c`` for a straight noiseless one.

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
    return _clipped_weight(*rim_noise_ratio(vertices, triangles))


def _clipped_weight(ratio: float, coverage: float) -> float:
    # the rim weight of measured_boundary_weight from rim_noise_ratio's (ratio, coverage)
    return 1.0 if not np.isfinite(ratio) else float(np.clip(ratio, SCAN_BOUNDARY_WEIGHT, coverage))


class NoiseEstimate(NamedTuple):
    """Noise and surface detail along the normal, in edge lengths (:func:`measured_noise`)."""

    noise: float
    detail: float


#: :func:`measured_noise` forms the 2-ring pattern in this many blocks of rows (a 16th of it at a time),
#: of at least ``_NOISE_BLOCK`` rows.
_NOISE_BLOCKS = 16
_NOISE_BLOCK = 1 << 16
#: :func:`measured_noise` averages over every k-th vertex of those two rings from the rim, k the least
#: that leaves at most this many (a mean of 2**14 vertices is within a percent of all of them)
_NOISE_ROWS = 1 << 14


def measured_noise(
    vertices: np.ndarray, triangles: np.ndarray, *, structure: _Structure | None = None
) -> NoiseEstimate:
    """The noise's deviation and the surface's own detail at the edge scale, both from the mesh.

    Two umbrella vectors of each vertex ``i`` at least two rings from the rim,
    along its normal ``n_i``: ``a1 = n_i . (mean of the 1-ring - x_i)`` and
    ``a2 = n_i . (mean of the 2-ring - x_i)`` (the 2-ring: every vertex
    within two edges). For i.i.d. noise ``sigma`` on a smooth surface of 1-ring umbrella ``g``,
    ``E a1^2 = sigma^2 (1 + 1/d1) + g^2`` and ``E a2^2 = sigma^2 (1 + 1/d2) + G g^2``, ``G =
    (mean squared 2-ring distance / mean squared 1-ring distance)^2`` (about 7): two equations
    for ``sigma^2`` and ``g^2``. Normals (area-weighted) and distances are taken after one umbrella
    step; both results are divided by the RMS 1-ring distance ``h``. Measured: ``sigma`` within
    0.01-0.04 edge lengths at 0.2 and 0.5 noise; ``g`` 0.05 on bunny, screwdriver, feline, 0.10 on
    the coarse Venus. Scale-free. ``(0, 0)`` when no vertex is two rings from the rim. The means run
    over every k-th of those vertices, at most ``2**14`` of them.

    Examples
    --------
    >>> import numpy as np, open3d as o3d
    >>> sphere = o3d.geometry.TriangleMesh.create_sphere(radius=1.0, resolution=40)
    >>> V, F = np.asarray(sphere.vertices), np.asarray(sphere.triangles).astype(np.int64)
    >>> h = np.linalg.norm(V[F[:, 0]] - V[F[:, 1]], axis=1).mean()
    >>> estimate = measured_noise(V + np.random.default_rng(0).normal(0.0, 0.3 * h, V.shape), F)
    >>> 0.25 < estimate.noise < 0.35
    True
    """
    n = len(vertices)
    st = _structure(triangles, n) if structure is None else structure
    lo, hi = st.edges[:, 0], st.edges[:, 1]
    ring = sp.csr_matrix((np.ones(2 * len(lo)), (np.r_[lo, hi], np.r_[hi, lo])), shape=(n, n))
    inner = (st.valence > 0) & ~st.boundary
    inner[ring[st.boundary].indices] = False  # two rings from the rim: full 1- and 2-rings
    if not inner.any():
        return NoiseEstimate(0.0, 0.0)
    d1 = st.valence.astype(np.float64)
    referenced = st.valence > 0
    ring_sum = ring @ vertices
    smooth = vertices.copy()
    smooth[referenced] += ring_sum[referenced] / d1[referenced, None] - vertices[referenced]
    smooth_square = np.einsum("ij,ij->i", smooth, smooth)
    normal = area_weighted_normals(smooth, triangles)
    inner_rows = np.flatnonzero(inner)
    inner_rows = inner_rows[:: -(-len(inner_rows) // _NOISE_ROWS)]
    # per inner vertex: 1-ring umbrella along the normal, and the 1-ring's mean squared distance
    sub, x = smooth[inner_rows], vertices[inner_rows]
    nrm = normal[inner_rows]
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), np.finfo(float).tiny)
    di = d1[inner_rows]
    a1 = np.einsum("ij,ij->i", ring_sum[inner_rows] / di[:, None] - x, nrm)
    h2 = float(
        np.mean(
            _mean_square_distances((ring @ smooth_square)[inner_rows], (ring @ smooth)[inner_rows], sub, di)
        )
    )
    if not h2 > 0.0:
        return NoiseEstimate(0.0, 0.0)
    del ring_sum, sub, x
    # the same over the 2-ring (every vertex within two edges), a block of rows at a time: the whole
    # 2-ring pattern (about 19 entries a row, with its product and sum) took 800 bytes a vertex
    sum_a2, sum_k2, sum_h2 = 0.0, 0.0, 0.0
    # a few blocks, not blocks of a fixed size: each product clears a work array as long as the mesh
    block_rows = max(_NOISE_BLOCK, -(-len(inner_rows) // _NOISE_BLOCKS))
    for start in range(0, len(inner_rows), block_rows):
        rows = inner_rows[start : start + block_rows]
        block = ring[rows]
        two = block @ ring + block
        two.data[:] = 1.0
        own = np.repeat(rows, np.diff(two.indptr)) == two.indices  # the vertex itself is not its neighbour
        two.data[own] = 0.0
        two.eliminate_zeros()
        d2 = np.diff(two.indptr).astype(np.float64)
        a2 = np.einsum(
            "ij,ij->i", two @ vertices / d2[:, None] - vertices[rows], nrm[start : start + len(rows)]
        )
        sum_a2 += float(a2 @ a2)
        sum_k2 += float(np.sum(1.0 + 1.0 / d2))
        sum_h2 += float(np.sum(_mean_square_distances(two @ smooth_square, two @ smooth, smooth[rows], d2)))
    count = len(inner_rows)
    growth = (sum_h2 / count / h2) ** 2
    k1, k2 = float(np.mean(1.0 + 1.0 / di)), sum_k2 / count
    e1, e2 = float(np.mean(a1 * a1)), sum_a2 / count
    detail = max((e2 - e1 * k2 / k1) / (growth - k2 / k1), 0.0) if growth > k2 / k1 else 0.0
    noise = max((e1 - detail) / k1, 0.0)
    return NoiseEstimate(float(np.sqrt(noise / h2)), float(np.sqrt(detail / h2)))


def _mean_square_distances(
    square_sums: np.ndarray, sums: np.ndarray, points: np.ndarray, counts: np.ndarray
) -> np.ndarray:
    """Mean of ``|y_j - p|^2`` over each point's neighbours ``y_j``, from the neighbours' sums of
    ``|y|^2`` and of ``y`` and their counts: ``(sum |y|^2 - 2 p . sum y) / count + |p|^2``, ``(k,)``."""
    return (square_sums - 2.0 * np.einsum("ij,ij->i", sums, points)) / counts + np.einsum(
        "ij,ij->i", points, points
    )


def scan_likeness(rim_ratio: float, boundary_fraction: float) -> float:
    """How much the mesh looks like one raw range scan, from 0 (not at all) to 1 (``scan_parameters``).

    The product of two ramps, linear in the logarithm of their measure: the rim's unclipped data
    weight (:func:`rim_noise_ratio`) from 1 at ``SCAN_RIM_RATIO[0]`` to 0 at ``SCAN_RIM_RATIO[1]``
    (0.07-0.13 on the bunny scans, whose silhouettes are 2.5-4 times noisier; i.i.d. noise gives
    about 2), and the fraction of boundary vertices from 0 at ``SCAN_BOUNDARY_FRACTION[0]`` to 1 at
    ``SCAN_BOUNDARY_FRACTION[1]`` (7-13% on a range scan). A closed mesh gives 0.
    """

    def ramp(value: float, zero: float, one: float) -> float:
        with np.errstate(divide="ignore"):
            return float(np.clip(np.log(value / zero) / np.log(one / zero), 0.0, 1.0))

    low, high = SCAN_RIM_RATIO
    rim = ramp(rim_ratio, high, low)
    fraction = ramp(boundary_fraction, *SCAN_BOUNDARY_FRACTION)
    return rim * fraction


@dataclass(frozen=True)
class ScanParameters:
    """The weights of the scan energy that :func:`scan_parameters` measured on a mesh.

    Attributes
    ----------
    mu, membrane, boundary_weight : float
        The energy's ``mu``, ``lambda`` and rim ``w_t``.
    twicing : float
        Weight ``t`` of the twicing step, ``X = X1 + t S (X0 - X1)``.
    rim_curve : float
        Weight of the boundary-curve Laplacian in a rim vertex's thin-plate
        row (:func:`scan_system`).
    scan_likeness : float
        ``s`` of :func:`scan_likeness`.
    noise, detail : float
        ``sigma`` and ``g`` of :func:`measured_noise`.
    """

    mu: float
    membrane: float
    boundary_weight: float
    twicing: float
    rim_curve: float
    scan_likeness: float
    noise: float
    detail: float


def scan_parameters(
    vertices: np.ndarray, triangles: np.ndarray, *, structure: _Structure | None = None
) -> ScanParameters:
    """Every weight of the default energy, measured on the mesh (never on a reference).

    A raw range scan (``s = 1``, :func:`scan_likeness`) gets the energy
    measured on the scans: ``mu = SCAN_MU (g / sigma)^2`` (at least ``SCAN_RIM_MU``, at most 1;
    ``g / sigma`` the detail-to-noise ratio of :func:`measured_noise`, so a scan of finer detail than
    its noise is held closer to its samples), the rim triangles' ``mu w_t = SCAN_RIM_MU w``,
    ``lambda = SCAN_MEMBRANE``, twicing ``t = 1``: the membrane damps the scanline-correlated
    noise that the thin-plate term keeps. A mesh with independent noise (``s = 0``: a
    closed mesh, or a rim as noisy as its interior) gets the barycenter-only
    energy (``lambda = 0``, no twicing) with ``mu = NOISE_MU_SCALE (g / sigma)^NOISE_MU_POWER``
    in ``MU_RANGE`` (:func:`measured_noise`; measured on bunny, screwdriver and feline at 0.2 and
    0.5 mean-edge noise, benchmarks/results/denoise.md). Between the two every weight moves with
    ``s`` (``mu`` and the rim's weight geometrically). ``w`` is :func:`measured_boundary_weight`. All measures are
    dimensionless: the parameters are invariant under rigid motions and uniform scaling.

    Examples
    --------
    >>> import numpy as np, open3d as o3d
    >>> sphere = o3d.geometry.TriangleMesh.create_sphere(radius=1.0, resolution=40)
    >>> V, F = np.asarray(sphere.vertices), np.asarray(sphere.triangles).astype(np.int64)
    >>> p = scan_parameters(V + np.random.default_rng(0).normal(0.0, 0.01, V.shape), F)
    >>> p.scan_likeness, p.membrane, p.twicing  # closed: independent noise
    (0.0, 0.0, 0.0)
    """
    n = len(vertices)
    st = _structure(triangles, n) if structure is None else structure
    ratio, coverage = rim_noise_ratio(vertices, triangles, structure=st)
    weight = _clipped_weight(ratio, coverage)
    referenced = int(np.count_nonzero(st.valence))
    fraction = float(np.count_nonzero(st.boundary)) / max(referenced, 1)
    s = scan_likeness(ratio, fraction)
    estimate = measured_noise(vertices, triangles, structure=st)
    ratio_gn = estimate.detail / estimate.noise if estimate.noise > 0.0 else np.inf
    independent = float(np.clip(NOISE_MU_SCALE * ratio_gn**NOISE_MU_POWER, *MU_RANGE))
    # never below the rim's weight: the interior's samples are at least as trustworthy as the ragged rim's,
    # and a weaker pull lets the membrane shrink a smooth, coarsely sampled scan (a ball scanned at 60 x 60
    # rays moved 0.24 grid spacings inward at mu = 0.003, 0.015 at SCAN_RIM_MU)
    scan = float(np.clip(SCAN_MU * ratio_gn**2, SCAN_RIM_MU, MU_RANGE[1]))
    mu = float(np.exp((1.0 - s) * np.log(independent) + s * np.log(scan)))
    # a scan's rim triangles keep the weight SCAN_RIM_MU w whatever the interior's mu
    rim = weight * (SCAN_RIM_MU / scan) ** s
    return ScanParameters(mu, s * SCAN_MEMBRANE, rim, s, 1.0 - s, s, estimate.noise, estimate.detail)


class _Penalized:
    penalty: sp.csr_matrix  # (m, n) sqrt(mu W) H: the rows that carry the targets

    def normal_rhs(self, positions0: np.ndarray) -> np.ndarray:
        """``R^T T = mu H^T W H X0``, ``(n, 3)``."""
        return self.penalty.T @ (self.penalty @ positions0)


@dataclass(frozen=True)
class ScanSystem(_Penalized):
    """The scan energy as weighted least-squares equations, per coordinate.

    ``E(X) = |R X - T|^2`` with the stacked rows ``R = [sqrt(mu W) H;
    sqrt(lambda) D; (unit rows); K]`` (``D`` the ``(e, n)``
    edge-difference matrix) and
    targets ``T = [sqrt(mu W) H X0; 0; ...]``, so the normal matrix is
    ``R^T R = mu H^T W H + lambda D^T D + K^T K`` (``D^T D`` is the
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


def scan_system(
    triangles: np.ndarray,
    n: int,
    *,
    mu: float,
    membrane: float,
    boundary_weight: float,
    structure: _Structure | None = None,
    rim_curve: float = 0.0,
) -> ScanSystem:
    """The least-squares rows of the scan energy for ``(m, 3) int64`` triangles on ``n`` vertices.

    No manifold condition: an edge of three or more triangles is an interior
    edge (it is not on the boundary), a vertex joining several fans has the
    union of their neighbours as its 1-ring. Built from one edge list, in
    ``O(n + m)``.
    """
    m = len(triangles)
    edges, counts, boundary, valence, _ = _structure(triangles, n) if structure is None else structure
    edges = edges.astype(np.int64)  # row numbers below pass 2**31 before the vertex indices do
    e = len(edges)
    lo, hi = edges[:, 0], edges[:, 1]
    referenced = valence > 0
    unreferenced = np.flatnonzero(~referenced)
    inverse = np.zeros(n)
    np.divide(1.0, valence, out=inverse, where=referenced)
    weight = np.where(boundary[triangles].any(axis=1), float(boundary_weight), 1.0)  # (m,) w_t
    root = np.sqrt(mu * weight)
    membrane_root = np.sqrt(membrane)
    ref_rows = np.flatnonzero(referenced)
    # rows [0, m): sqrt(mu w_t) at t's corners; [m, m+e): sqrt(lambda) (x_lo - x_hi); a unit row per
    # unreferenced vertex; then K (row i: 1 at i, -1/n_i at each neighbour)
    u = len(unreferenced)
    row = [np.repeat(np.arange(m), 3), m + np.arange(e), m + np.arange(e), m + e + np.arange(u)]
    col = [triangles.ravel(), lo, hi, unreferenced]
    data = [np.repeat(root, 3), np.full(e, membrane_root), np.full(e, -membrane_root), np.ones(u)]
    count = m + e + u
    # a rim vertex's row mixes its one-sided Laplacian (weight 1 - t) with the Laplacian along its
    # boundary curve (weight t = rim_curve): the one-sided row pulls a straight rim inward, the curve
    # row does not
    t = float(rim_curve)
    row_weight = np.where(boundary, 1.0 - t, 1.0) * inverse
    row += [count + ref_rows, count + lo, count + hi]
    col += [ref_rows, hi, lo]
    data += [np.ones(len(ref_rows)), -row_weight[lo], -row_weight[hi]]
    if t > 0.0:
        curve = edges[counts == 1]
        curve_inverse = _curve_inverse(curve, n, t)
        row += [count + curve[:, 0], count + curve[:, 1]]
        col += [curve[:, 1], curve[:, 0]]
        data += [-curve_inverse[curve[:, 0]], -curve_inverse[curve[:, 1]]]
    shape = (count + n, n)
    rows = sp.csr_matrix((np.concatenate(data), (np.concatenate(row), np.concatenate(col))), shape=shape)
    return ScanSystem(rows, _penalty(triangles, n, root), referenced, boundary, weight)


def _curve_inverse(curve: np.ndarray, n: int, t: float) -> np.ndarray:
    """``t / c_i`` for the ``c_i`` boundary-curve neighbours of each vertex (0 off the curve), ``(n,)``."""
    valence = np.bincount(curve.ravel(), minlength=n)
    return np.divide(t, valence, out=np.zeros(n), where=valence > 0)


def _penalty(triangles: np.ndarray, n: int, root: np.ndarray) -> sp.csr_matrix:
    """``sqrt(mu W) H`` for ``root = sqrt(mu w_t)``, ``(m, n)`` CSR."""
    corners = np.arange(0, 3 * len(triangles) + 1, 3)
    return sp.csr_matrix((np.repeat(root, 3), triangles.ravel(), corners), shape=(len(triangles), n))


def scan_normal_matrix(
    triangles: np.ndarray,
    n: int,
    *,
    mu: float,
    membrane: float,
    boundary_weight: float,
    structure: _Structure | None = None,
    rim_curve: float = 0.0,
) -> sp.csr_matrix:
    """The normal matrix ``R^T R`` of :func:`scan_system`, assembled from the mesh's edges, ``(n, n)`` CSR.

    ``R^T R = mu H^T W H + lambda G + K^T K`` (plus a unit diagonal entry per unreferenced
    vertex) without forming ``R``: ``(H^T W H)_ij`` sums ``w_t`` over the triangles on edge ``ij``
    (at ``i`` when ``i = j``), scattered straight into the 1-ring CSR pattern
    (:func:`~o3d_lsmesh.topology.ring_pattern`); only ``K^T K`` (the 2-ring) is a sparse product.
    Canonical and symmetric (its arrays are also the CSC form's); equal to
    ``scan_system(...).normal_matrix()`` to round-off. A triangle repeating a vertex is left to
    :func:`scan_system`.

    Examples
    --------
    >>> import numpy as np
    >>> F = np.array([[0, 1, 2], [0, 2, 3]])
    >>> N = scan_normal_matrix(F, 5, mu=0.03, membrane=0.45, boundary_weight=0.1)
    >>> S = scan_system(F, 5, mu=0.03, membrane=0.45, boundary_weight=0.1).normal_matrix()
    >>> bool(abs(N - S).max() < 1e-15), N.shape
    (True, (5, 5))
    """
    return _normal_matrix(triangles, n, mu, membrane, boundary_weight, structure, rim_curve)[0]


def _normal_matrix(
    triangles: np.ndarray,
    n: int,
    mu: float,
    membrane: float,
    boundary_weight: float,
    structure: _Structure | None = None,
    rim_curve: float = 0.0,
) -> tuple[sp.csr_matrix, sp.csc_matrix | None, np.ndarray]:
    # scan_normal_matrix; the pattern of K (the 1-ring, diagonal included) when K^T K holds the matrix's;
    # the (m,) triangle weights w_t
    triangles = np.asarray(triangles)
    if collapsed_triangles(triangles).any():
        rows = scan_system(
            triangles,
            n,
            mu=mu,
            membrane=membrane,
            boundary_weight=boundary_weight,
            structure=structure,
            rim_curve=rim_curve,
        )
        return rows.normal_matrix().tocsr(), None, rows.triangle_weight
    st = _structure(triangles, n) if structure is None else structure
    edges, counts, boundary, valence, halfedge_edge = st
    lo, hi = edges[:, 0], edges[:, 1]
    referenced = valence > 0
    indptr, indices, diagonal, forward, backward = ring_pattern(edges, n)
    weight = np.where(boundary[triangles].any(axis=1), float(boundary_weight), 1.0)  # (m,) w_t
    # mu H^T W H + lambda G (+ 1 on an unreferenced vertex's diagonal), on the 1-ring pattern
    data = np.empty(len(indices))
    data[diagonal] = mu * np.bincount(triangles.ravel(), np.repeat(weight, 3), minlength=n)
    data[diagonal] += membrane * valence
    data[diagonal[~referenced]] = 1.0
    # half-edge a * m + t is triangle t's edge from corner a: its weights are np.tile(w, 3)
    on_edge = mu * np.bincount(halfedge_edge, np.tile(weight, 3), minlength=len(edges)) - membrane
    data[forward] = on_edge
    data[backward] = on_edge
    matrix = sp.csr_matrix((data, indices, indptr), shape=(n, n))
    # K: row i is 1 at i and -(1 - t) / n_i - t / c_i at each neighbour (the second part only across
    # boundary edges, c_i of them; t = rim_curve for a rim vertex, the one-sided row otherwise)
    t = float(rim_curve)
    inverse = np.zeros(n)
    np.divide(np.where(boundary, 1.0 - t, 1.0), valence, out=inverse, where=referenced)
    plate = np.empty(len(indices))
    plate[diagonal] = referenced
    plate[forward] = -inverse[lo]
    plate[backward] = -inverse[hi]
    if t > 0.0:
        rim = counts == 1
        curve_inverse = _curve_inverse(edges[rim], n, t)
        plate[forward[rim]] -= curve_inverse[lo[rim]]
        plate[backward[rim]] -= curve_inverse[hi[rim]]
    # K's CSR arrays are K^T's CSC: K^T K by the compiled product on every core (SciPy's took 2 s at
    # 1.4M); symmetric, so its CSC arrays are its CSR ones. Its pattern holds the 1-ring (K_ii K_ij), so
    # the 1-ring terms are added into it in place (a sum would make a third 2-ring matrix)
    from .. import _block_kernel  # compiled by the package's build: imported where used

    square = gram_matrix(sp.csc_matrix((plate, indices, indptr), shape=(n, n)))
    del plate
    index = square.indices.dtype
    missing = _block_kernel.add_subset(
        square.indptr,
        square.indices,
        square.data,
        matrix.indptr.astype(index, copy=False),
        matrix.indices.astype(index, copy=False),
        matrix.data,
    )
    assert missing == 0, "the 1-ring lies within K^T K's pattern"
    del matrix
    ring = sp.csc_matrix((np.ones(len(indices)), indices, indptr), shape=(n, n))
    normal = sp.csr_matrix((square.data, square.indices, square.indptr), shape=(n, n))
    normal.has_sorted_indices = True  # canonical: CHOLMOD and the lower-triangle cut need it
    return normal, ring, weight


def _lower_csc(symmetric: sp.csr_matrix) -> sp.csc_matrix:
    """The lower triangle of a symmetric canonical CSR matrix as CSC: its upper CSR triangle, reinterpreted."""
    n = symmetric.shape[0]
    rows = np.repeat(np.arange(n, dtype=symmetric.indices.dtype), np.diff(symmetric.indptr))
    keep = symmetric.indices >= rows
    indptr = np.zeros(n + 1, dtype=symmetric.indptr.dtype)
    np.cumsum(np.bincount(rows[keep], minlength=n), out=indptr[1:])
    return sp.csc_matrix((symmetric.data[keep], symmetric.indices[keep], indptr), shape=(n, n))


class ScanFairingSolver(_Penalized):
    """The scan energy factored once; :meth:`solve` faires positions with it.

    Parameters
    ----------
    triangles : (m, 3) int64
    n : int
        Vertex count (unreferenced vertices stay where they are).
    mu, membrane, boundary_weight : float
        ``mu``, ``lambda`` and the boundary triangles' ``w_t`` of the energy
        (see the module docstring).
    solver : {"auto", "cholmod", "iterative"}
        ``"iterative"``: block conjugate gradients preconditioned by the
        matrix's incomplete Cholesky factor, started from the scan, each solve
        to :data:`SCAN_REDUCTION` of its starting residual. ``"auto"``: that
        from :data:`SCAN_ITERATIVE_VERTICES` vertices, CHOLMOD (exact) below.
    progress : bool
        Show the iterative solves' residual in a tqdm bar.

    Notes
    -----
    ``R^T R`` is positive definite: on each component the only null vector of ``K^T K`` and ``G``
    is the constant, and ``1^T H^T W H 1 = 9 sum_t w_t > 0``. CHOLMOD factors the lower triangle
    of :func:`scan_normal_matrix`, analyzed as ``K^T K`` from the 1-ring pattern with COLAMD
    (10-15% fewer factor flops than AMD, same analysis time; METIS's 30% fewer cost an analysis
    longer than the factor). The factor's flops grow like a component's size to the power 1.5
    and its two solves serve one call, while the data term on every vertex keeps the matrix's
    condition number independent of the size: IC(0)-preconditioned CG takes 6-11 iterations a
    solve at every size (linear work) and stops where its error is far below the noise removed
    (:data:`SCAN_REDUCTION`). 40k-vertex scans: 0.14-0.27 s against 0.31-0.57 s by the factor;
    1.4M vertices: 8.0 s against 21.5 s (the AMG V-cycle: 12.3 s)
    (benchmarks/results/realscans_denoise_speed.md). The object pickles and its solves are
    serialized by a lock.
    """

    def __init__(
        self,
        triangles: np.ndarray,
        n: int,
        *,
        mu: float,
        membrane: float,
        boundary_weight: float,
        structure: _Structure | None = None,
        rim_curve: float = 0.0,
        solver: str = "auto",
        progress: bool = False,
    ) -> None:
        self.mu = float(mu)
        self.membrane = float(membrane)
        backend = solver_backend(solver)
        triangles = np.asarray(triangles)
        st = _structure(triangles, n) if structure is None else structure
        normal, ring, weight = _normal_matrix(
            triangles, n, self.mu, self.membrane, boundary_weight, st, rim_curve
        )
        self.penalty = _penalty(triangles, n, np.sqrt(self.mu * weight))
        self.referenced = st.valence > 0
        if backend == "auto" and n >= SCAN_ITERATIVE_VERTICES:
            backend = "iterative"
        if backend == "iterative":
            # symmetric and canonical: its CSR arrays are its CSC form (no copy); CG runs on the whole
            # matrix, numbered by the 1-ring's reverse Cuthill-McKee order (a scan's is scattered)
            whole = sp.csc_matrix((normal.data, normal.indices, normal.indptr), shape=normal.shape)
            del normal
            self._solver = SPDSolver(
                whole,
                backend=backend,
                preconditioner="ic0",
                reduction=SCAN_REDUCTION,
                locality_of=ring,
                progress=progress,
            )
            return
        # COLAMD on K's 1-ring pattern (see Notes): at 1.4M vertices 46.5 against 51.4 GFlop with AMD on the
        # matrix (METIS 35.2 but a 15 s analysis). The assembled lower triangle, not ``product_of`` rows: from
        # the rows the memory estimate of ``backend="auto"`` guessed 3x the entries and went iterative (4x
        # slower). CG preconditioned by the factor of the 1-ring part alone was measured slower.
        self._solver = SPDSolver(
            _lower_csc(normal),
            lower=True,
            backend=backend,
            ordering="amd" if ring is None else "colamd",
            pattern_of=ring,
            progress=progress,
        )

    @property
    def backend(self) -> str:
        """The solver that runs: ``"cholmod"``, ``"scipy"`` or ``"iterative"``."""
        return self._solver.backend

    def filter(self, positions0: np.ndarray) -> np.ndarray:
        """``S X0``: the minimizer of the energy for targets ``X0``, ``(n, 3)`` (unreferenced rows kept)."""
        return self.solve(positions0, twice=False)

    def _filter(self, rhs: np.ndarray, positions0: np.ndarray) -> np.ndarray:
        # the iterative path starts from the targets (the scan, close to its faired self) and solves
        # the displacement from them to SCAN_REDUCTION; a start worse than zero is dropped per column by
        # the gateway; direct solvers ignore it
        return self._solver.solve(rhs, x0=positions0)

    def solve(
        self, positions0: np.ndarray, *, number_of_iterations: int = 1, twice: bool | float = True
    ) -> np.ndarray:
        """``number_of_iterations`` filter passes (targets re-taken each time), then the twicing step.

        ``twice`` is the twicing weight ``t`` of ``X = X1 + t S (X0 - X1)``
        (``True`` is 1, ``False`` 0: no second back-substitution).
        """
        given = np.asarray(positions0, dtype=np.float64)
        # solved about the centroid (``K 1 = 0``, the other terms are differences: ``S`` commutes with
        # translations), so the iterative path's relative residual measures the shape, not the distance
        # to the origin: a scan in world coordinates, 1e6 sizes away, lost 0.2% of its size before
        centre = given[self.referenced].mean(axis=0) if self.referenced.any() else np.zeros(3)
        targets = given - centre
        positions = targets
        for _ in range(number_of_iterations):
            positions = self._filter(self.normal_rhs(positions), positions)
        weight = float(twice)
        if weight and number_of_iterations:
            rest = targets - positions
            positions = positions + weight * self._filter(self.normal_rhs(rest), rest)
        out = positions + centre
        unused = ~self.referenced
        out[unused] = given[unused]  # exactly where they were
        return out


def scan_denoise(
    vertices: np.ndarray,
    triangles: np.ndarray,
    *,
    number_of_iterations: int = 1,
    mu: float | None = None,
    membrane: float | None = None,
    boundary_weight: float | None = None,
    solver: str = "auto",
    progress: bool = False,
) -> np.ndarray:
    """The default denoiser on arrays: :func:`scan_parameters`, one system, the twiced filter.

    ``mu``, ``membrane`` and ``boundary_weight`` replace the measured values
    when given (the twicing weight stays the measured one). One edge list
    serves the measures and the system; ``solver`` and ``progress`` as in
    :class:`ScanFairingSolver`. Returns new ``(n, 3) float64`` positions.

    Examples
    --------
    >>> import numpy as np, open3d as o3d
    >>> box = o3d.geometry.TriangleMesh.create_box()
    >>> V, F = np.asarray(box.vertices), np.asarray(box.triangles).astype(np.int64)
    >>> scan_denoise(V, F).shape
    (8, 3)
    """
    n = len(vertices)
    # at 10M vertices the measures and the assembly take tens of seconds before CG shows its residual
    with stages(progress, "constrained fairing (scan)", ("measure", "assemble", "solve")) as begin:
        begin("measure")
        structure = _structure(triangles, n)
        measured = scan_parameters(vertices, triangles, structure=structure)
        begin("assemble")
        system = ScanFairingSolver(
            triangles,
            n,
            mu=measured.mu if mu is None else mu,
            membrane=measured.membrane if membrane is None else membrane,
            boundary_weight=measured.boundary_weight if boundary_weight is None else boundary_weight,
            structure=structure,
            rim_curve=measured.rim_curve,
            solver=solver,
            progress=progress,
        )
        begin("solve")
        out = system.solve(vertices, number_of_iterations=number_of_iterations, twice=measured.twicing)
        # a rim as noisy as the interior (s = 0) is not pulled in: its sweeps are off
        return relax_rim(vertices, out, triangles, structure=structure, strength=measured.scan_likeness)


#: :func:`relax_rim` relaxes the vertices up to this many edges from the rim, by as many sweeps (one
#: sweep reaches one ring further).
RIM_RINGS = 3


def triangle_quality(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """``4 sqrt(3) area / (sum of squared edges)`` of each triangle, ``(m,)``: 1 equilateral, 0 degenerate.

    >>> triangle_quality(np.array([[0.0, 0, 0], [1, 0, 0], [0.5, 0.75**0.5, 0]]), np.array([[0, 1, 2]])).round(12)
    array([1.])
    """
    a = vertices[triangles[:, 0]]
    ab, ac = vertices[triangles[:, 1]] - a, vertices[triangles[:, 2]] - a
    twice_area = np.linalg.norm(np.cross(ab, ac), axis=1)
    bc = ac - ab
    squares = np.einsum("ij,ij->i", ab, ab) + np.einsum("ij,ij->i", ac, ac) + np.einsum("ij,ij->i", bc, bc)
    return 2.0 * np.sqrt(3.0) * twice_area / np.maximum(squares, np.finfo(float).tiny)


def relax_rim(
    scan: np.ndarray,
    positions: np.ndarray,
    triangles: np.ndarray,
    *,
    strength: float = 1.0,
    structure: _Structure | None = None,
) -> np.ndarray:
    """Even out the triangles near the rim of a faired scan, moving each vertex in its tangent plane only.

    The scan energy pulls a ragged silhouette in along the surface by one to three edge lengths (most
    of its gain at the rim), which squeezes the rim's triangles into slivers. With ``n_i`` the unit
    (area-weighted) normal of ``positions`` at each vertex, held fixed:

    1. :data:`RIM_RINGS` damped Jacobi sweeps ``x_i += (a/2) P_i (mean of the neighbours - x_i)``
       (``a = strength`` in ``[0, 1]``; :func:`scan_denoise` gives the scan likeness),
       ``P_i = I - n_i n_i^T``, on the vertices within :data:`RIM_RINGS` edges of the rim; a rim
       vertex's neighbours are its boundary-curve neighbours (it slides along the rim, which its
       1-ring would pull inward).
    2. While a triangle's quality (:func:`triangle_quality`) is below ``min(SLIVER_QUALITY, its
       quality in the scan)``, each of its vertices in that band gives back a further quarter of the tangential
       part of its move from the scan ``s_i``: ``x_i = p_i - (k/4) P_i (p_i - s_i)``, ``k <= 4``
       (at ``k = 4`` it keeps only its fairing along ``n_i``).

    Every vertex's move from ``positions`` lies in its tangent plane (``n_i . (x_i - p_i) = 0``), so
    no vertex leaves the faired surface's tangent plane (where the fairing shrank a vertex's triangles
    to a point, below ``sqrt(eps)`` of their area in the scan, ``n_i`` is the scan's normal there; a
    vertex with neither stays). Equivariant under rigid motions and uniform
    scaling. ``scan``, ``positions``: ``(n, 3)`` float64; returns new ``(n, 3)`` positions.

    Examples
    --------
    >>> import numpy as np
    >>> g = np.stack(np.meshgrid(np.arange(6.0), np.arange(6.0), indexing="ij"), -1).reshape(-1, 2)
    >>> F = np.array([[i * 6 + j, i * 6 + j + 6, i * 6 + j + 1] for i in range(5) for j in range(5)]
    ...              + [[i * 6 + j + 1, i * 6 + j + 6, i * 6 + j + 7] for i in range(5) for j in range(5)])
    >>> scan = np.c_[g, np.zeros(36)]
    >>> squeezed = scan.copy(); squeezed[:6, 0] = 0.99  # the first rim row pulled onto the second
    >>> int((triangle_quality(squeezed, F) < SLIVER_QUALITY).sum()), int((triangle_quality(relax_rim(scan, squeezed, F), F) < SLIVER_QUALITY).sum())
    (10, 0)
    """
    n = len(positions)
    st = _structure(triangles, n) if structure is None else structure
    out = np.array(positions, dtype=np.float64)
    if not st.boundary.any():
        return out

    # the band: vertices within RIM_RINGS edges of the rim; only its vertices move, so only the triangles
    # at them (their whole fans) are read
    def at(mask: np.ndarray, faces: np.ndarray) -> np.ndarray:  # faces with a vertex in the mask
        return mask[faces[:, 0]] | mask[faces[:, 1]] | mask[faces[:, 2]]

    band = st.boundary.copy()
    for _ in range(RIM_RINGS):
        band[triangles[at(band, triangles)]] = True
    near = triangles[at(band, triangles)]
    normal = area_weighted_normals(out, near)
    length = np.linalg.norm(normal, axis=1)
    # a fan the fairing shrank to a point (a lone triangle of the scan), its area under sqrt(eps) of the
    # scan's (then its normal is round-off), takes the scan's tangent plane
    scan_normal = area_weighted_normals(scan, near)
    scan_length = np.linalg.norm(scan_normal, axis=1)
    flat = length <= np.sqrt(np.finfo(float).eps) * scan_length
    normal[flat], length[flat] = scan_normal[flat], scan_length[flat]
    del scan_normal, scan_length
    movable = band & (length > 0.0)  # a vertex without a tangent plane stays
    normal[movable] /= length[movable, None]

    def tangential(move: np.ndarray, rows: np.ndarray) -> np.ndarray:
        return move - np.einsum("ij,ij->i", move, normal[rows])[:, None] * normal[rows]

    # a rim vertex averages its neighbours along the rim, any other vertex its 1-ring
    lo, hi = st.edges[:, 0].astype(np.int64), st.edges[:, 1].astype(np.int64)
    on_curve = np.tile(st.counts == 1, 2)
    rows, cols = np.r_[lo, hi], np.r_[hi, lo]
    keep = movable[rows] & (~st.boundary[rows] | on_curve)
    neighbours = sp.csr_matrix((np.ones(int(keep.sum())), (rows[keep], cols[keep])), shape=(n, n))
    count = np.diff(neighbours.indptr)
    moved = np.flatnonzero(count)
    neighbours = neighbours[moved]
    share = 0.5 * strength / count[moved, None]
    for _ in range(RIM_RINGS):
        out[moved] += tangential(share * (neighbours @ out) - 0.5 * strength * out[moved], moved)
    # where a triangle still degenerates, its vertices give back their tangential drift from the scan, a
    # quarter at a time (all of it at once left five bunny scans 1.3 um further from the truth on average)
    given_back = np.where(movable, 0, 4)
    candidates = near
    while True:
        # only the triangles at a vertex moved in the last round can have changed
        quality = triangle_quality(out, candidates)
        low = candidates[quality < SLIVER_QUALITY]
        corners = np.unique(low[quality[quality < SLIVER_QUALITY] < triangle_quality(scan, low)])
        corners = corners[given_back[corners] < 4]
        if not len(corners):
            return out
        given_back[corners] += 1
        drift = tangential(positions[corners] - scan[corners], corners)
        out[corners] = positions[corners] - 0.25 * given_back[corners, None] * drift
        touched = np.zeros(n, dtype=bool)
        touched[corners] = True
        candidates = near[at(touched, near)]
