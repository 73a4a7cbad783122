"""Type stub of the compiled hole-filling kernel (``_fill_kernel.pyx``)."""

from typing import Any

import numpy as np

def delaunay_triangles(points: np.ndarray) -> np.ndarray | None: ...
def minimum_weight_triangulation(
    points: np.ndarray,
    outer_normals: np.ndarray,
    forbidden: np.ndarray | None = None,
    allowed: np.ndarray | None = None,
) -> np.ndarray: ...
def relax(
    points: np.ndarray, triangles: np.ndarray, fixed_pairs: np.ndarray, dirty: np.ndarray
) -> np.ndarray: ...
def refine(
    points: np.ndarray,
    sigma: np.ndarray,
    triangles: np.ndarray,
    fixed_pairs: np.ndarray,
    owner: np.ndarray,
    alpha: float,
    max_points: int = -1,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...
def refine_budget(points: np.ndarray, triangles: np.ndarray, sigma: np.ndarray) -> int: ...
def tangential_relax(
    vertices: np.ndarray, new_tris: np.ndarray, first_new: int, iterations: int = 10
) -> np.ndarray: ...
def rings(
    triangles: np.ndarray, indptr: np.ndarray, data: np.ndarray, seeds: np.ndarray, count: int
) -> tuple[np.ndarray, list[np.ndarray]]: ...
def laplacian_weights(
    tris: np.ndarray,
    nv: int,
    i: np.ndarray,
    j: np.ndarray,
    inverse: np.ndarray,
    vertices: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...
def loop_geometry(
    loop: np.ndarray,
    rows: np.ndarray,
    vertices: np.ndarray,
    triangles: np.ndarray,
    indptr: np.ndarray,
    data: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, np.ndarray]: ...
def unique_edges(tris: np.ndarray, nv: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...
def keeps_facing(x: np.ndarray, again: np.ndarray, new_tris: np.ndarray) -> bool: ...
def patch_system(
    x: np.ndarray,
    tris: np.ndarray,
    i: np.ndarray,
    j: np.ndarray,
    inverse: np.ndarray,
    unknown: np.ndarray,
    ring0: np.ndarray,
    ring1: np.ndarray,
    level: int,
    cot: bool,
    dense: bool,
) -> tuple[Any, np.ndarray]: ...
def patch_crossings(
    vertices: np.ndarray,
    triangles: np.ndarray,
    first_new: int,
    grids: list[tuple[np.ndarray, float, np.ndarray, np.ndarray, np.ndarray, float]],
    tri_centre: np.ndarray,
    tri_radius: np.ndarray,
    new_grids: list[tuple[np.ndarray, float, np.ndarray, np.ndarray, np.ndarray, float]],
    new_centre: np.ndarray,
    new_radius: np.ndarray,
    owner: np.ndarray | None = None,
) -> np.ndarray: ...
def local_mesh(
    triangles: np.ndarray, first_new: int, ring_tris: np.ndarray, rings: list[np.ndarray], nv: int
) -> tuple[np.ndarray, np.ndarray, list[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]: ...
def ring_mesh(
    triangles: np.ndarray,
    indptr: np.ndarray,
    data: np.ndarray,
    seeds: np.ndarray,
    count: int,
    all_triangles: np.ndarray,
    nv: int,
) -> tuple[np.ndarray, np.ndarray, list[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]: ...
