"""Generated test shapes (fixed seeds, no mesh files): the demo's bumpy blob, a simulated range scan of
it, seeded noise, and the mean edge length noise is measured in.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._o3d.io import cast_rays, icosphere, legacy_mesh, raycasting_scene
from ..core import arrays

__all__ = ["add_noise", "demo_mesh", "mean_edge_length", "simulated_range_scan"]


def demo_mesh(subdivisions: int = 6, *, seed: int = 7) -> Any:
    """The built-in scan-like test surface as a legacy ``open3d.geometry.TriangleMesh``.

    A unit icosahedron midpoint-subdivided ``subdivisions`` times (``10 * 4**subdivisions + 2``
    vertices) on the sphere, displaced by smooth lobes, eight seeded Gaussian bumps and a ring of
    sharp creases: closed, genus 0, well-shaped triangles.

    >>> mesh = demo_mesh(3)
    >>> len(mesh.vertices), mesh.is_watertight()
    (642, True)
    """
    directions, triangles = icosphere(subdivisions)
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    x, y, z = directions.T
    radius = 1.0 + 0.12 * np.sin(2.0 * x + 1.0) * np.cos(3.0 * y) + 0.10 * z**2
    rng = np.random.default_rng(seed)
    centers = rng.normal(size=(8, 3))
    centers /= np.linalg.norm(centers, axis=1, keepdims=True)
    angle = np.arccos(np.clip(directions @ centers.T, -1.0, 1.0))
    radius += 0.08 * np.exp(-0.5 * (angle / 0.12) ** 2).sum(axis=1)
    # A band of creases around the equator: |sin| has kinks, the sharp features a scan would hold.
    band = np.exp(-0.5 * (z / 0.18) ** 2)
    radius += 0.05 * band * (1.0 - np.abs(np.sin(6.0 * np.arctan2(y, x))))
    return legacy_mesh(directions * radius[:, None], triangles)


def mean_edge_length(mesh: Any) -> float:
    """Mean length of the triangles' edges (an interior edge counted twice): the unit noise is given in.

    >>> round(mean_edge_length(demo_mesh(0)), 3)  # the icosahedron, displaced
    1.098
    """
    return arrays.mean_edge_length(np.asarray(mesh.vertices), np.asarray(mesh.triangles))


def add_noise(mesh: Any, sigma: float, *, seed: int = 0) -> Any:
    """A copy of ``mesh`` with seeded isotropic Gaussian noise of standard deviation ``sigma`` on every vertex."""
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    noisy = vertices + np.random.default_rng(seed).normal(scale=sigma, size=vertices.shape)
    return legacy_mesh(noisy, np.asarray(mesh.triangles))


def simulated_range_scan(
    resolution: int = 200, *, noise: float = 0.3, seed: int = 0, subdivisions: int = 6
) -> tuple[Any, Any]:
    """A raw range scan of :func:`demo_mesh` from one view, and the surface it was scanned from.

    Parallel rays on a ``resolution x resolution`` grid, triangulated as range scans are (two
    triangles per cell whose corners hit, none across a depth jump): range noise of ``noise`` grid
    spacings growing at grazing angles and correlated along scanlines, a ragged silhouette, islands
    and dropout holes. Returns ``(scan, surface)``, both legacy Open3D meshes.

    >>> scan, surface = simulated_range_scan(60)
    >>> len(scan.vertices) > 1000, scan.is_watertight(), surface.is_watertight()
    (True, False, True)
    """
    surface = demo_mesh(subdivisions)
    vertices = np.asarray(surface.vertices)
    triangles = np.asarray(surface.triangles)
    rng = np.random.default_rng(seed)
    # Rays along -z on a square grid a little wider than the blob's silhouette.
    half = 1.05 * np.abs(vertices[:, :2]).max()
    spacing = 2.0 * half / (resolution - 1)
    u = np.linspace(-half, half, resolution)
    x, y = np.meshgrid(u, u)  # row i is a scanline: y fixed, x running
    origins = np.stack([x, y, np.full_like(x, 10.0)], axis=-1).reshape(-1, 3)
    directions = np.broadcast_to([0.0, 0.0, -1.0], origins.shape)
    answer = cast_rays(raycasting_scene(vertices, triangles), np.hstack([origins, directions]))
    depth = answer["t_hit"].astype(np.float64)
    cosine = np.abs(answer["primitive_normals"][:, 2].astype(np.float64))
    hit = np.isfinite(depth) & (cosine > 0.1)
    # Grazing returns drop out at random: the ragged silhouette (and its islands) of a real scan.
    hit &= rng.random(hit.shape) > np.clip((0.35 - cosine) / 0.5, 0.0, 1.0)
    # A few patches of lost returns inside the view (specular dropouts): holes with ragged rims.
    for _ in range(4):
        centre, radius = rng.uniform(-0.5 * half, 0.5 * half, 2), rng.uniform(2.0, 5.0) * spacing
        inside = (origins[:, 0] - centre[0]) ** 2 + (origins[:, 1] - centre[1]) ** 2 < radius**2
        hit &= ~(inside & (rng.random(hit.shape) < 0.9))
    # Range noise: white, plus a per-scanline offset and a drift along each line, larger at grazing angles.
    white = rng.normal(size=(resolution, resolution))
    offset = rng.normal(size=(resolution, 1))
    # a drift along each line: white noise averaged over 9 samples (a cumulative sum's differences)
    walk = np.cumsum(np.pad(rng.normal(size=(resolution, resolution + 8)), ((0, 0), (1, 0))), axis=1)
    drift = (walk[:, 9:] - walk[:, :-9]) / 3.0
    correlated = 0.7 * white + 0.5 * offset + 0.5 * drift
    sigma = noise * spacing / np.maximum(cosine, 0.1) ** 1.5
    depth_noisy = np.where(hit, depth + sigma * correlated.ravel(), np.nan)
    points = origins + depth_noisy[:, None] * directions
    # Two triangles per grid cell whose corners all hit and whose depths do not jump (range-scan meshing).
    index = np.arange(resolution * resolution).reshape(resolution, resolution)
    a, b = index[:-1, :-1].ravel(), index[:-1, 1:].ravel()
    c, d = index[1:, :-1].ravel(), index[1:, 1:].ravel()
    cells = np.concatenate([np.stack([a, b, c], axis=1), np.stack([b, d, c], axis=1)])
    keep = hit[cells].all(axis=1)
    cells = cells[keep]
    jump = np.ptp(depth[cells], axis=1) < 4.0 * spacing
    cells = cells[jump]
    used, inverse = np.unique(cells, return_inverse=True)
    return legacy_mesh(points[used], inverse.reshape(-1, 3)), surface
