"""Measures of a mesh's noise that set the weights of the scan default (:func:`scan_parameters`).

Noise and detail along the normal, the rim's noise against the interior's, the scan likeness; all
dimensionless, never taken from a reference. Docs: ``docs/algorithms/scan_denoiser.rst``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..core.arrays import area_weighted_normals
from ..core.connectivity import Connectivity
from ..core.operators import two_ring_sums, umbrella
from .tuning import (
    MU_RANGE,
    NOISE_BLOCK,
    NOISE_BLOCKS,
    NOISE_MU_POWER,
    NOISE_MU_SCALE,
    NOISE_ROWS,
    SCAN_BOUNDARY_FRACTION,
    SCAN_BOUNDARY_WEIGHT,
    SCAN_MEMBRANE,
    SCAN_MU,
    SCAN_RIM_MU,
    SCAN_RIM_RATIO,
)

__all__ = [
    "NoiseEstimate",
    "ScanParameters",
    "measured_boundary_weight",
    "measured_noise",
    "rim_noise_ratio",
    "scan_likeness",
    "scan_parameters",
]

# Expected ratio (boundary curve / interior) of the mean squared uniform Laplacian for i.i.d. noise of
# one variance: a curve vertex's (x_(i-1) + x_(i+1)) / 2 - x_i has variance 1.5 sigma^2, an interior
# vertex of valence 6 has (1 + 1/6) sigma^2.
_IID_BOUNDARY_RATIO = 1.5 / (1.0 + 1.0 / 6.0)


def _mean_square_laplacian(vertices: np.ndarray, pairs: np.ndarray, mask: np.ndarray) -> float:
    """Mean over the ``mask`` vertices of ``|mean of the pairs-neighbours - x_i|^2``."""
    lap = umbrella(vertices, pairs, mask)
    return float((lap * lap).sum(axis=1).mean())


def rim_noise_ratio(
    vertices: np.ndarray, triangles: np.ndarray, *, conn: Connectivity | None = None
) -> tuple[float, float]:
    """The rim's data weight before clipping, ``c (9/7) E_int / E_bd``, and the coverage ratio ``c``.

    ``(inf, 1)`` without a boundary or an interior vertex, ``(c, c)`` for a noiseless straight rim.
    """
    n = len(vertices)
    conn = Connectivity(triangles, n) if conn is None else conn
    boundary, valence = conn.rim
    on_curve = conn.edges[conn.boundary_edges]
    interior = (valence > 0) & ~boundary
    if not len(on_curve) or not interior.any():
        return float("inf"), 1.0
    in_triangles = np.bincount(triangles.ravel(), minlength=n)
    coverage = max(1.0, float(in_triangles[interior].mean() / in_triangles[boundary].mean()))
    curve_energy = _mean_square_laplacian(vertices, on_curve, boundary)
    if curve_energy <= 0.0:
        return coverage, coverage
    interior_energy = _mean_square_laplacian(vertices, conn.edges, interior)
    return coverage * _IID_BOUNDARY_RATIO * interior_energy / curve_energy, coverage


def measured_boundary_weight(vertices: np.ndarray, triangles: np.ndarray) -> float:
    """The rim triangles' barycenter weight ``w = clip(c (9/7) E_int / E_bd, SCAN_BOUNDARY_WEIGHT, c)``
    (docs page); 1 without a boundary. ``vertices (n, 3)``, ``triangles (m, 3)``.

    >>> import open3d as o3d
    >>> box = o3d.geometry.TriangleMesh.create_box()
    >>> measured_boundary_weight(np.asarray(box.vertices), np.asarray(box.triangles))
    1.0
    """
    return _clipped_weight(*rim_noise_ratio(vertices, triangles))


def _clipped_weight(ratio: float, coverage: float) -> float:
    # the rim weight of measured_boundary_weight from rim_noise_ratio's (ratio, coverage)
    return 1.0 if not np.isfinite(ratio) else float(np.clip(ratio, SCAN_BOUNDARY_WEIGHT, coverage))


class NoiseEstimate(NamedTuple):
    """Noise and surface detail along the normal, in edge lengths (:func:`measured_noise`)."""

    noise: float
    detail: float


def measured_noise(
    vertices: np.ndarray, triangles: np.ndarray, *, conn: Connectivity | None = None
) -> NoiseEstimate:
    """The noise ``sigma`` and the surface's detail ``g`` along the normal, in RMS edge lengths, from the
    1- and 2-ring umbrellas of at most ``NOISE_ROWS`` vertices two rings from the rim (else ``(0, 0)``);
    the 2-ring formed ``NOISE_BLOCK`` rows or more at a time. Derivation: ``docs/algorithms/scan_denoiser.rst``.

    >>> import open3d as o3d
    >>> s = o3d.geometry.TriangleMesh.create_sphere(radius=1.0, resolution=30)
    >>> V = np.asarray(s.vertices) + np.random.default_rng(0).normal(0.0, 0.02, (len(s.vertices), 3))
    >>> round(measured_noise(V, np.asarray(s.triangles)).noise, 2)
    0.19
    """
    n = len(vertices)
    conn = Connectivity(triangles, n) if conn is None else conn
    boundary, valence = conn.rim
    ring = conn.adjacency
    inner = (valence > 0) & ~boundary
    inner[ring[boundary].indices] = False  # two rings from the rim: full 1- and 2-rings
    if not inner.any():
        return NoiseEstimate(0.0, 0.0)
    d1 = valence.astype(np.float64)
    referenced = valence > 0
    with np.errstate(divide="ignore", invalid="ignore"):  # an unreferenced row (0 / 0) is not taken
        mean = (ring @ vertices) / d1[:, None]
    # whole rows, not a boolean selection of each (n, 3) array
    smooth = np.where(referenced[:, None], vertices + (mean - vertices), vertices)
    # about the centroid: the mean squared distances are formed from sums of squares, whose round-off
    # grows with the distance to the origin (a scan in world coordinates)
    smooth -= (referenced @ smooth) / max(int(referenced.sum()), 1)  # a product: no selected copy
    smooth_square = np.einsum("ij,ij->i", smooth, smooth)
    inner_rows = np.flatnonzero(inner)
    inner_rows = inner_rows[:: -(-len(inner_rows) // NOISE_ROWS)]
    # the sampled rows' normals from their own triangles alone (the same sums in the same order)
    sampled = np.zeros(n, dtype=bool)
    sampled[inner_rows] = True
    normal = area_weighted_normals(smooth, triangles[sampled[triangles].any(axis=1)])
    # per inner vertex: 1-ring umbrella along the normal, and the 1-ring's mean squared distance
    sub, x = smooth[inner_rows], vertices[inner_rows]
    nrm = normal[inner_rows]
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), np.finfo(float).tiny)
    di = d1[inner_rows]
    a1 = np.einsum("ij,ij->i", mean[inner_rows] - x, nrm)
    stacked = np.column_stack([vertices, smooth, smooth_square])  # the 2-ring sums of all three in one pass
    # the 1-ring sums of the sampled rows only (the same sums in the same order as the whole product's)
    sums = ring[inner_rows] @ stacked
    near = _mean_square_distances(sums[:, 6], sums[:, 3:6], sub, di)
    h2 = float(np.mean(near))
    if not h2 > 0.0:
        return NoiseEstimate(0.0, 0.0)
    del mean, sub, x, near, sums
    # the same over the 2-ring (every vertex within two edges), a block of rows at a time (the whole
    # 2-ring pattern, with its product and sum, is several times the mesh)
    sum_a2, sum_k2, sum_h2 = 0.0, 0.0, 0.0
    # a few blocks, not blocks of a fixed size: each product clears a work array as long as the mesh
    block_rows = max(NOISE_BLOCK, -(-len(inner_rows) // NOISE_BLOCKS))
    for start in range(0, len(inner_rows), block_rows):
        part = inner_rows[start : start + block_rows]
        d2, sums = two_ring_sums(ring, part, stacked)
        a2 = np.einsum("ij,ij->i", sums[:, :3] / d2[:, None] - vertices[part], nrm[start : start + len(part)])
        # not a BLAS dot: OpenBLAS wakes its threads for long vectors, and they spin afterwards, which costs
        # twice the call's time beside busy processes (benchmarks/results/under_load.md)
        sum_a2 += float(np.square(a2).sum())
        sum_k2 += float(np.sum(1.0 + 1.0 / d2))
        sum_h2 += float(np.sum(_mean_square_distances(sums[:, 6], sums[:, 3:6], smooth[part], d2)))
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
    """How much the mesh looks like one raw range scan, 0 to 1: two log-linear ramps over ``SCAN_RIM_RATIO``
    (:func:`rim_noise_ratio`) and ``SCAN_BOUNDARY_FRACTION`` (of boundary vertices), multiplied."""

    def ramp(value: float, zero: float, one: float) -> float:
        with np.errstate(divide="ignore"):
            return float(np.clip(np.log(value / zero) / np.log(one / zero), 0.0, 1.0))

    return ramp(rim_ratio, *SCAN_RIM_RATIO[::-1]) * ramp(boundary_fraction, *SCAN_BOUNDARY_FRACTION)


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
        row (:func:`o3d_lsmesh.core.operators.scan_normal_matrix`).
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
    vertices: np.ndarray, triangles: np.ndarray, *, conn: Connectivity | None = None
) -> ScanParameters:
    """Every weight of the default energy, measured on the mesh: a range scan's (scan likeness ``s = 1``),
    independent noise's (``s = 0``) or in between (docs page).

    >>> import open3d as o3d
    >>> sphere = o3d.geometry.TriangleMesh.create_sphere(radius=1.0, resolution=20)
    >>> scan_parameters(np.asarray(sphere.vertices), np.asarray(sphere.triangles)).scan_likeness
    0.0
    """
    n = len(vertices)
    conn = Connectivity(triangles, n) if conn is None else conn
    boundary, valence = conn.rim
    ratio, coverage = rim_noise_ratio(vertices, triangles, conn=conn)
    weight = _clipped_weight(ratio, coverage)
    referenced = int(np.count_nonzero(valence))
    fraction = float(np.count_nonzero(boundary)) / max(referenced, 1)
    s = scan_likeness(ratio, fraction)
    estimate = measured_noise(vertices, triangles, conn=conn)
    ratio_gn = estimate.detail / estimate.noise if estimate.noise > 0.0 else np.inf
    independent = float(np.clip(NOISE_MU_SCALE * ratio_gn**NOISE_MU_POWER, *MU_RANGE))
    # never below the rim's weight: the interior's samples are at least as trustworthy as the ragged rim's,
    # and a weaker pull lets the membrane shrink a smooth, coarsely sampled scan
    scan = float(np.clip(SCAN_MU * ratio_gn**2, SCAN_RIM_MU, MU_RANGE[1]))
    mu = float(np.exp((1.0 - s) * np.log(independent) + s * np.log(scan)))
    # a scan's rim triangles keep the weight SCAN_RIM_MU w whatever the interior's mu
    rim = weight * (SCAN_RIM_MU / scan) ** s
    return ScanParameters(mu, s * SCAN_MEMBRANE, rim, s, 1.0 - s, s, estimate.noise, estimate.detail)
