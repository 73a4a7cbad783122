import numpy as np

Array = np.ndarray

def minimum_weight_triangulation(
    points: Array, outer_normals: Array, forbidden: Array | None = None, allowed: Array | None = None
) -> Array: ...
def delaunay_allowed(points: Array, tets: Array, centre: Array, cospherical: float) -> Array | None: ...
def relax(points: Array, triangles: Array, fixed_pairs: Array, dirty: Array, smooth: bool = ...) -> Array: ...
def refine(
    points: Array,
    sigma: Array,
    triangles: Array,
    fixed_pairs: Array,
    owner: Array,
    alpha: float,
    max_points: int = -1,
) -> tuple[Array, Array, Array]: ...
def loop_geometry(
    loop_: Array, rows: Array, vertices_: Array, triangles: Array, indptr: Array, data: Array
) -> tuple[Array, Array, Array, float, Array]: ...
