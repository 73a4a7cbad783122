"""Type stub of the compiled feature kernel (``_feature_kernel.pyx``)."""

import numpy as np

def ring_spacing(indptr: np.ndarray, indices: np.ndarray, centroid: np.ndarray) -> float: ...
def filtered_normals(
    indptr: np.ndarray,
    indices: np.ndarray,
    centroid: np.ndarray,
    guide: np.ndarray,
    area: np.ndarray,
    normals: np.ndarray,
    range_divisor: float,
    space_divisor: float,
    out: np.ndarray,
) -> None: ...
def least_dot(indptr: np.ndarray, indices: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray: ...
def ring_least(indptr: np.ndarray, indices: np.ndarray, values: np.ndarray) -> np.ndarray: ...
def plane_steps(
    corners: np.ndarray,
    indptr: np.ndarray,
    faces: np.ndarray,
    normals: np.ndarray,
    x: np.ndarray,
    iterations: int,
) -> None: ...
def pair_jumps(pairs: np.ndarray, normals: np.ndarray) -> np.ndarray: ...
def patch_pairs(
    indptr: np.ndarray,
    indices: np.ndarray,
    first_indptr: np.ndarray,
    first_pairs: np.ndarray,
    second: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]: ...
def patch_saliency(indptr: np.ndarray, pairs: np.ndarray, jump: np.ndarray) -> np.ndarray: ...
