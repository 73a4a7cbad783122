import numpy as np

Array = np.ndarray

def tangential_relax(vertices: Array, new_tris: Array, first_new: int, iterations: int = 10) -> Array: ...
def local_mesh(
    triangles: Array, indptr: Array, data: Array, seeds: Array, count: int, new_tris: Array
) -> tuple[Array, Array, list[Array]]: ...
def patch_system(
    x: Array, tris: Array, unknown: Array, ring0: Array, ring1: Array, level: int, cot: bool, dense: bool
) -> tuple[Array | tuple[Array, Array, Array], Array]: ...
def triangle_grids(
    vertices: Array, triangles: Array
) -> tuple[Array, Array, list[tuple[Array, float, Array, Array, Array, float]]]: ...
def patch_crossings(
    vertices: Array,
    triangles: Array,
    first_new: int,
    grids: list[tuple[Array, float, Array, Array, Array, float]],
    tri_centre: Array,
    tri_radius: Array,
    new_grids: list[tuple[Array, float, Array, Array, Array, float]],
    new_centre: Array,
    new_radius: Array,
    owner: Array | None = None,
) -> Array: ...
