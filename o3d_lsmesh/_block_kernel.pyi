"""Type stub of the compiled block kernel (``_block_kernel.pyx``)."""

from typing import Any, Literal, overload

import numpy as np

def block_product(
    indptr: np.ndarray,
    indices: np.ndarray,
    data: np.ndarray,
    x: np.ndarray,
    out: np.ndarray,
    scale: float = 1.0,
    offset: np.ndarray | None = None,
) -> None: ...
def empty_small_pages(shape: Any, dtype: Any = ..., fill: Any = None) -> np.ndarray: ...
def symmetry_gap(
    indptr: np.ndarray, indices: np.ndarray, data: np.ndarray
) -> tuple[float, int, int, int]: ...
def column_dots(a: np.ndarray, b: np.ndarray) -> np.ndarray: ...
def cg_direction(p: np.ndarray, z: np.ndarray, beta: np.ndarray) -> None: ...
def gauss_seidel(
    indptr: np.ndarray,
    indices: np.ndarray,
    data: np.ndarray,
    x: np.ndarray,
    b: np.ndarray,
    forward: bool,
    blocks: int = 1,
) -> None: ...
def cg_step(
    x: np.ndarray, r: np.ndarray, p: np.ndarray, q: np.ndarray, alpha: np.ndarray, w: np.ndarray
) -> np.ndarray: ...
def strong_part(
    indptr: np.ndarray, indices: np.ndarray, data: np.ndarray, theta: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...
def incomplete_cholesky(
    indptr: np.ndarray, indices: np.ndarray, data: np.ndarray, shift: float
) -> tuple[np.ndarray | None, np.ndarray | None, int]: ...
def incomplete_cholesky_solve(
    indptr: np.ndarray, indices: np.ndarray, L: np.ndarray, diag: np.ndarray, r: np.ndarray, z: np.ndarray
) -> None: ...
def row_span(indptr: np.ndarray, indices: np.ndarray) -> float: ...
def permuted(
    indptr: np.ndarray, indices: np.ndarray, data: np.ndarray, order: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...
def level_order(indptr: np.ndarray, indices: np.ndarray) -> np.ndarray: ...
def gram(
    row_ptr: np.ndarray,
    row_cols: np.ndarray,
    row_data: np.ndarray,
    col_ptr: np.ndarray,
    col_rows: np.ndarray,
    col_data: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...
def pair_product(
    indptr: np.ndarray,
    indices: np.ndarray,
    a: np.ndarray,
    xa: np.ndarray,
    b: np.ndarray,
    xb: np.ndarray,
    offset: np.ndarray,
    out: np.ndarray,
) -> None: ...
def add_subset(
    indptr: np.ndarray,
    indices: np.ndarray,
    data: np.ndarray,
    sub_indptr: np.ndarray,
    sub_indices: np.ndarray,
    sub_data: np.ndarray,
) -> int: ...
def area_normals(positions: np.ndarray, triangles: np.ndarray) -> np.ndarray: ...
def edge_sums(edges: np.ndarray, values: np.ndarray) -> np.ndarray: ...
def two_ring_sums(
    indptr: np.ndarray, indices: np.ndarray, rows: np.ndarray, values: np.ndarray
) -> tuple[np.ndarray, np.ndarray]: ...
@overload
def triangle_normals(
    positions: np.ndarray, triangles: np.ndarray, centroids: Literal[True]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...
@overload
def triangle_normals(
    positions: np.ndarray, triangles: np.ndarray, centroids: Literal[False] = False
) -> tuple[np.ndarray, np.ndarray, None]: ...
