"""Generated test shapes: the demo's bumpy blob, seeded noise, and the mean edge length noise is measured in.

The demo, the examples and the tests use these instead of shipping mesh files:
every shape is made by code with fixed seeds.

>>> mesh = demo_mesh(2)
>>> noisy = add_noise(mesh, 0.1 * mean_edge_length(mesh), seed=1)
>>> len(noisy.vertices), len(noisy.triangles)
(162, 320)
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ._o3d import open3d

__all__ = ["add_noise", "demo_mesh", "mean_edge_length"]


def demo_mesh(subdivisions: int = 6, *, seed: int = 7) -> Any:
    """The built-in scan-like test surface as a legacy ``open3d.geometry.TriangleMesh``.

    A unit icosahedron midpoint-subdivided ``subdivisions`` times
    (``10 * 4**subdivisions + 2`` vertices: 40,962 for 6), projected to the
    sphere and displaced along the radius by smooth lobes, eight Gaussian
    bumps at seeded directions and a ring of creases (``|sin|`` profile, so
    the creases are sharp). Closed, genus 0, well-shaped triangles.

    Examples
    --------
    >>> mesh = demo_mesh(3)
    >>> len(mesh.vertices), mesh.is_watertight()
    (642, True)
    """
    o3d = open3d()
    mesh = o3d.geometry.TriangleMesh.create_icosahedron(radius=1.0)
    if subdivisions:
        mesh = mesh.subdivide_midpoint(number_of_iterations=int(subdivisions))
    directions = np.asarray(mesh.vertices, dtype=np.float64)
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
    out = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(directions * radius[:, None]), o3d.geometry.TriangleMesh(mesh).triangles
    )
    return out


def mean_edge_length(mesh: Any) -> float:
    """Mean length of the triangles' edges (an interior edge counted twice): the unit noise is given in.

    >>> round(mean_edge_length(demo_mesh(0)), 3)  # the icosahedron, displaced
    1.098
    """
    vertices = np.asarray(mesh.vertices)
    triangles = np.asarray(mesh.triangles)
    edges = vertices[triangles[:, [1, 2, 0]]] - vertices[triangles]
    return float(np.linalg.norm(edges, axis=2).mean())


def add_noise(mesh: Any, sigma: float, *, seed: int = 0) -> Any:
    """A copy of ``mesh`` with seeded isotropic Gaussian noise of standard deviation ``sigma`` on every vertex."""
    o3d = open3d()
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    noisy = vertices + np.random.default_rng(seed).normal(scale=sigma, size=vertices.shape)
    return o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(noisy), o3d.geometry.TriangleMesh(mesh).triangles
    )
